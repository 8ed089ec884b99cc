//! A real mosquitto broker and the real mosquitto_pub / mosquitto_sub clients for tests.

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use super::process::lines_of;

/// A mosquitto process on a port of its own.
pub struct Mosquitto {
    child: Option<Child>,
    /// Its port on 127.0.0.1.
    pub port: u16,
    /// Listener settings (mosquitto.conf lines) and the folder its config goes in, if any.
    settings: Option<(String, PathBuf)>,
    /// Arguments every mosquitto_pub / mosquitto_sub needs (CA file, credentials).
    client_args: Vec<String>,
}

/// A certificate authority and a broker certificate for 127.0.0.1, made with openssl.
pub struct TestPki {
    /// The CA certificate (PEM).
    pub ca: PathBuf,
    /// The broker's certificate (PEM), for 127.0.0.1 and localhost.
    pub cert: PathBuf,
    /// The broker's key (PEM).
    pub key: PathBuf,
    /// The CA's key, which signs the certificates.
    ca_key: PathBuf,
    dir: PathBuf,
    name: String,
}

/// Runs openssl with `args` in `dir`.
fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("openssl runs");
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

impl TestPki {
    /// Makes a CA called `name` and a broker certificate it signs, in `dir`.
    pub fn create(dir: &Path, name: &str) -> TestPki {
        let (ca, ca_key) = (format!("{name}-ca.pem"), format!("{name}-ca.key"));
        openssl(
            dir,
            &[
                "req",
                "-x509",
                "-newkey",
                "rsa:2048",
                "-nodes",
                "-days",
                "2",
                "-subj",
                &format!("/CN={name} test CA"),
                "-keyout",
                &ca_key,
                "-out",
                &ca,
            ],
        );
        let mut pki = TestPki {
            ca: dir.join(ca),
            cert: PathBuf::new(),
            key: PathBuf::new(),
            ca_key: dir.join(ca_key),
            dir: dir.to_owned(),
            name: name.to_owned(),
        };
        (pki.cert, pki.key) = pki.issue(
            "broker",
            "localhost",
            "subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\n",
        );
        pki
    }

    /// A client certificate and key the CA signs for `common_name` (a broker that takes the
    /// certificate's identity as the user name sees it as that user).
    pub fn client(&self, common_name: &str) -> (PathBuf, PathBuf) {
        self.issue(common_name, common_name, "extendedKeyUsage=clientAuth\n")
    }

    /// A certificate (and its key) for `common_name` with the `extensions`, files named after
    /// `what`.
    fn issue(&self, what: &str, common_name: &str, extensions: &str) -> (PathBuf, PathBuf) {
        let file = |suffix: &str| format!("{}-{what}.{suffix}", self.name);
        let (cert, key, csr, ext) = (file("pem"), file("key"), file("csr"), file("ext"));
        openssl(
            &self.dir,
            &[
                "req",
                "-newkey",
                "rsa:2048",
                "-nodes",
                "-subj",
                &format!("/CN={common_name}"),
                "-keyout",
                &key,
                "-out",
                &csr,
            ],
        );
        std::fs::write(self.dir.join(&ext), extensions).expect("extensions file");
        openssl(
            &self.dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                &self.ca.display().to_string(),
                "-CAkey",
                &self.ca_key.display().to_string(),
                "-CAcreateserial",
                "-days",
                "2",
                "-extfile",
                &ext,
                "-out",
                &cert,
            ],
        );
        (self.dir.join(cert), self.dir.join(key))
    }
}

/// mosquitto settings that refuse anonymous clients and accept `user` / `password` (a
/// password file written in `dir`).
fn password_settings(dir: &Path, user: &str, password: &str) -> String {
    format!(
        "allow_anonymous false\npassword_file {}\n",
        password_file(dir, &[(user, password)]).display()
    )
}

/// A mosquitto password file in `dir` holding `users` (name, password).
fn password_file(dir: &Path, users: &[(&str, &str)]) -> PathBuf {
    let passwd = dir.join("passwd");
    for (i, (user, password)) in users.iter().enumerate() {
        let create: &[&str] = if i == 0 { &["-c", "-b"] } else { &["-b"] };
        let status = Command::new("mosquitto_passwd")
            .args(create)
            .arg(&passwd)
            .args([user, password])
            .stderr(Stdio::null())
            .status()
            .expect("mosquitto_passwd runs");
        assert!(status.success(), "mosquitto_passwd failed");
    }
    passwd
}

/// A port nobody listens on right now.
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

impl Mosquitto {
    /// Starts mosquitto on a free port and waits until it accepts connections. Tests run in
    /// parallel, so another test may take the same free port first: then it tries another.
    pub fn start() -> Mosquitto {
        Self::start_with(None, Vec::new())
    }

    /// The mosquitto_pub / mosquitto_sub helpers for a broker someone else runs on `port`
    /// (chassisd's embedded one).
    pub fn clients_for(port: u16) -> Mosquitto {
        Self::clients_with(port, &[])
    }

    /// As [`Mosquitto::clients_for`], each client run with `args` (credentials, CA file).
    pub fn clients_with(port: u16, args: &[&str]) -> Mosquitto {
        Mosquitto {
            child: None,
            port,
            settings: None,
            client_args: args.iter().map(|a| (*a).to_owned()).collect(),
        }
    }

    /// Starts mosquitto with TLS (the certificate of `pki`) and a password file holding
    /// `user` / `password`; anonymous clients are refused. Files go in `dir`.
    pub fn start_secured(dir: &Path, pki: &TestPki, user: &str, password: &str) -> Mosquitto {
        let settings = format!(
            "{}cafile {}\ncertfile {}\nkeyfile {}\n\
             # Started as root, mosquitto would drop to its own user, who cannot read the key.\n\
             user root\n",
            password_settings(dir, user, password),
            pki.ca.display(),
            pki.cert.display(),
            pki.key.display()
        );
        let client_args = vec![
            "--cafile".to_owned(),
            pki.ca.display().to_string(),
            "-u".to_owned(),
            user.to_owned(),
            "-P".to_owned(),
            password.to_owned(),
        ];
        Self::start_with(Some((settings, dir.to_owned())), client_args)
    }

    /// Starts mosquitto with TLS that requires a client certificate of `pki`'s CA, the
    /// certificate's common name as the user name, and the access control list `acl`; its
    /// clients connect with the certificate of `client` (a common name). Files go in `dir`.
    pub fn start_with_client_certificates(
        dir: &Path,
        pki: &TestPki,
        acl: &str,
        client: &str,
    ) -> Mosquitto {
        let acl_file = dir.join("acl");
        std::fs::write(&acl_file, acl).expect("acl written");
        let settings = format!(
            "cafile {}\ncertfile {}\nkeyfile {}\nrequire_certificate true\n\
             use_identity_as_username true\nacl_file {}\n\
             # Started as root, mosquitto would drop to its own user, who cannot read the key.\n\
             user root\n",
            pki.ca.display(),
            pki.cert.display(),
            pki.key.display(),
            acl_file.display()
        );
        let (cert, key) = pki.client(client);
        let client_args = [
            "--cafile".to_owned(),
            pki.ca.display().to_string(),
            "--cert".to_owned(),
            cert.display().to_string(),
            "--key".to_owned(),
            key.display().to_string(),
        ]
        .to_vec();
        Self::start_with(Some((settings, dir.to_owned())), client_args)
    }

    /// Starts mosquitto on plain TCP with a password file of `users` (name, password) and the
    /// access control list `acl`; its clients connect as the first user. Files go in `dir`.
    pub fn start_with_acl(dir: &Path, users: &[(&str, &str)], acl: &str) -> Mosquitto {
        let passwd = password_file(dir, users);
        let acl_file = dir.join("acl");
        std::fs::write(&acl_file, acl).expect("acl written");
        let settings = format!(
            "allow_anonymous false\npassword_file {}\nacl_file {}\n",
            passwd.display(),
            acl_file.display()
        );
        let (user, password) = users[0];
        let client_args = ["-u", user, "-P", password].map(str::to_owned).to_vec();
        Self::start_with(Some((settings, dir.to_owned())), client_args)
    }

    /// Starts mosquitto on plain TCP with a password file holding `user` / `password`;
    /// anonymous clients are refused. Files go in `dir`.
    pub fn start_with_password(dir: &Path, user: &str, password: &str) -> Mosquitto {
        let settings = password_settings(dir, user, password);
        let client_args = vec![
            "-u".to_owned(),
            user.to_owned(),
            "-P".to_owned(),
            password.to_owned(),
        ];
        Self::start_with(Some((settings, dir.to_owned())), client_args)
    }

    fn start_with(settings: Option<(String, PathBuf)>, client_args: Vec<String>) -> Mosquitto {
        for _ in 0..20 {
            let mut m = Mosquitto {
                child: None,
                port: free_port(),
                settings: settings.clone(),
                client_args: client_args.clone(),
            };
            if m.try_start() {
                return m;
            }
        }
        panic!("mosquitto could not get a port");
    }

    /// (Re)starts it on its port.
    pub fn restart(&mut self) {
        assert!(
            self.try_start(),
            "mosquitto could not listen on {} again",
            self.port
        );
    }

    /// Starts it on its port; false if the port is taken (mosquitto exits).
    fn try_start(&mut self) -> bool {
        let mut cmd = Command::new("mosquitto");
        match &self.settings {
            Some((settings, dir)) => {
                let conf = dir.join(format!("mosquitto-{}.conf", self.port));
                let text = format!("listener {} 127.0.0.1\n{settings}", self.port);
                std::fs::write(&conf, text).expect("mosquitto.conf");
                cmd.arg("-c").arg(conf);
            }
            None => {
                cmd.args(["-p", &self.port.to_string()]);
            }
        }
        let child = cmd
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto starts (apt-get install mosquitto)");
        self.child = Some(child);
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            // Our own mosquitto must be the one listening: if it exited, the port was taken.
            if let Some(c) = &mut self.child
                && c.try_wait().expect("mosquitto status").is_some()
            {
                self.child = None;
                return false;
            }
            if TcpStream::connect(("127.0.0.1", self.port)).is_ok() {
                std::thread::sleep(Duration::from_millis(50));
                let alive = self
                    .child
                    .as_mut()
                    .is_some_and(|c| c.try_wait().ok().flatten().is_none());
                if !alive {
                    self.child = None;
                }
                return alive;
            }
            assert!(Instant::now() < deadline, "mosquitto did not listen");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Kills it (SIGKILL) and waits for it to go.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// `host:port` for `chassisd sim --mqtt`.
    pub fn address(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    /// Publishes one message at QoS 1 with mosquitto_pub.
    pub fn publish(&self, topic: &str, payload: &str) {
        self.publish_with(topic, payload, &[]);
    }

    /// Publishes with extra mosquitto_pub arguments (e.g. `-r` for retained).
    pub fn publish_with(&self, topic: &str, payload: &str, extra: &[&str]) {
        let status = Command::new("mosquitto_pub")
            .args(["-h", "127.0.0.1", "-p", &self.port.to_string(), "-q", "1"])
            .args(&self.client_args)
            .args(["-t", topic, "-m", payload])
            .args(extra)
            .status()
            .expect("mosquitto_pub runs");
        assert!(status.success(), "mosquitto_pub failed");
    }

    /// Publishes the contents of a file (large payloads).
    pub fn publish_file(&self, topic: &str, file: &std::path::Path) {
        let status = Command::new("mosquitto_pub")
            .args(["-h", "127.0.0.1", "-p", &self.port.to_string(), "-q", "1"])
            .args(&self.client_args)
            .args(["-t", topic, "-f"])
            .arg(file)
            .status()
            .expect("mosquitto_pub runs");
        assert!(status.success(), "mosquitto_pub failed");
    }

    /// A root e-stop (messageType 101, `on` 1 or 0) to the simulator (`vehicleId` `sim`);
    /// its ack's code.
    pub fn sim_estop(&self, on: u8) -> i64 {
        let acks = self.subscribe(&["/root/sim/cmd/chassis/ack"]);
        self.publish(
            "/root/sim/cmd/chassis/set",
            &format!(r#"{{"messageId": 77, "timestamp": "x", "messageType": 101, "data": {on}}}"#),
        );
        let ack = acks
            .next_on("/root/sim/cmd/chassis/ack", Duration::from_secs(15))
            .expect("e-stop ack");
        let ack: serde_json::Value = serde_json::from_str(&ack).expect("JSON");
        ack["data"]["code"].as_i64().expect("code")
    }

    /// Subscribes with mosquitto_sub to `topics`; lines are `topic payload`.
    pub fn subscribe(&self, topics: &[&str]) -> Subscriber {
        let mut cmd = Command::new("mosquitto_sub");
        cmd.args([
            "-h",
            "127.0.0.1",
            "-p",
            &self.port.to_string(),
            "-v",
            "-q",
            "1",
        ]);
        cmd.args(&self.client_args);
        for t in topics {
            cmd.args(["-t", t]);
        }
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto_sub runs");
        let lines = lines_of(child.stdout.take().expect("piped"));
        // mosquitto_sub prints nothing once subscribed; give it a moment to subscribe.
        std::thread::sleep(Duration::from_millis(300));
        Subscriber { child, lines }
    }
}

impl Drop for Mosquitto {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A running mosquitto_sub.
pub struct Subscriber {
    child: Child,
    lines: Receiver<String>,
}

impl Subscriber {
    /// The next message within `wait`: (topic, payload).
    pub fn next(&self, wait: Duration) -> Option<(String, String)> {
        let line = self.lines.recv_timeout(wait).ok()?;
        let (topic, payload) = line.split_once(' ').unwrap_or((line.as_str(), ""));
        Some((topic.to_owned(), payload.to_owned()))
    }

    /// The next message on `topic` within `wait`, skipping others.
    pub fn next_on(&self, topic: &str, wait: Duration) -> Option<String> {
        let deadline = Instant::now() + wait;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.next(left) {
                Some((t, p)) if t == topic => return Some(p),
                Some(_) => {}
                None => return None,
            }
        }
        None
    }

    /// Drops everything received so far.
    pub fn clear(&self) {
        while self.lines.try_recv().is_ok() {}
    }
}

impl Drop for Subscriber {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A client written byte by byte, as an attacker's would be: CONNECT packets of any
/// version, identifier and credentials, and the broker's answer read raw.
pub mod raw {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::time::Duration;

    /// A CONNECT packet: MQTT `level` (4 = 3.1.1, 5 = 5.0), clean session, keep-alive 60 s.
    pub fn connect_packet(
        level: u8,
        client_id: &str,
        credentials: Option<(&str, &str)>,
    ) -> Vec<u8> {
        let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', level];
        body.push(if credentials.is_some() { 0xc2 } else { 0x02 });
        body.extend_from_slice(&60u16.to_be_bytes());
        if level == 5 {
            body.push(0);
        }
        let mut string = |s: &[u8]| {
            body.extend_from_slice(&(s.len() as u16).to_be_bytes());
            body.extend_from_slice(s);
        };
        string(client_id.as_bytes());
        if let Some((user, password)) = credentials {
            string(user.as_bytes());
            string(password.as_bytes());
        }
        chassisd::broker::wire::packet(0x10, &body)
    }

    /// Connects and sends `packet`; returns the socket and the CONNACK's return code (3.1.1)
    /// or reason code (5), or `None` when the broker closed without one.
    pub fn connect_with(port: u16, packet: &[u8]) -> (TcpStream, Option<u8>) {
        try_connect_with(port, packet).expect("connect and send CONNECT")
    }

    /// As [`connect_with`]; `None` when the connection or the CONNECT's sending failed.
    pub fn try_connect_with(port: u16, packet: &[u8]) -> Option<(TcpStream, Option<u8>)> {
        let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
        s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
        s.write_all(packet).ok()?;
        let mut head = [0u8; 2];
        if s.read_exact(&mut head).is_err() || head[0] != 0x20 {
            return Some((s, None));
        }
        let mut rest = vec![0u8; usize::from(head[1])];
        if s.read_exact(&mut rest).is_err() || rest.len() < 2 {
            return Some((s, None));
        }
        Some((s, Some(rest[1])))
    }

    /// [`connect_with`] a [`connect_packet`].
    pub fn connect(
        port: u16,
        level: u8,
        client_id: &str,
        credentials: Option<(&str, &str)>,
    ) -> (TcpStream, Option<u8>) {
        connect_with(port, &connect_packet(level, client_id, credentials))
    }
}
