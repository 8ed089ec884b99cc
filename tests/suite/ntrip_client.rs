//! `chassisd run` with `[ntrip]`: corrections from a small caster of the test's own
//! (`common::caster`) reach the GNSS receiver, a pseudo-terminal, as the valid frames the
//! caster served, whole and in order; the GGA goes up at the configured interval; a caster
//! that fails in any way (closes at once, goes silent after its 200, refuses the
//! credentials) is reported and retried slowly; and a replay of the recording writes the
//! same bytes the receiver got.

use crate::common;

use std::path::Path;
use std::time::{Duration, Instant};

use chassisd::devices::gnss::rtcm::RtcmFramer;
use chassisd::ntrip::chunked::Dechunker;
use common::caster::{Behaviour, Caster, PortReader};
use common::process::Proc;
use common::pty::Port;

const WAIT: Duration = Duration::from_secs(20);

/// ptys are opened and children spawned one test at a time (a fork in between would
/// inherit the pty's descriptors).
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());
    TURN.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The whole valid frames of `stream`, in order.
fn valid_frames(stream: &[u8]) -> Vec<u8> {
    let mut framer = RtcmFramer::new();
    let mut out = Vec::new();
    framer.push(stream, |f, _| out.extend_from_slice(f));
    out
}

/// `chassisd run` with the receiver on a pty at `dir/gnss` and `[ntrip]` of `ntrip`
/// (TOML lines); returns the daemon, what reaches the pty, and the pty's writer.
fn run_with_caster(
    dir: &Path,
    ntrip: &str,
    extra: &[&std::ffi::OsStr],
) -> (Proc, PortReader, std::fs::File) {
    let (daemon, master) = run_with_receiver(dir, ntrip, extra);
    let writer = master.try_clone().expect("the pty's writer");
    (daemon, PortReader::start(master), writer)
}

/// [`run_with_caster`], the pty's master handed back unread.
fn run_with_receiver(dir: &Path, ntrip: &str, extra: &[&std::ffi::OsStr]) -> (Proc, std::fs::File) {
    let link = dir.join("gnss");
    let config = dir.join("vehicle.toml");
    std::fs::write(
        &config,
        format!(
            "[gnss]\nport = \"{}\"\nreconnect_max_s = 0.2\n\n[ntrip]\n{ntrip}\n",
            link.display()
        ),
    )
    .expect("config");
    let _turn = one_at_a_time();
    let port = Port::open_at(&link);
    let mut args: Vec<&std::ffi::OsStr> =
        vec!["run".as_ref(), "--config".as_ref(), config.as_os_str()];
    args.extend_from_slice(extra);
    (Proc::start(&args), port.master)
}

/// A real reference station's stream with every seventh frame corrupted (one payload byte
/// flipped), and what must reach the receiver: the rest.
fn corrupted_stream() -> (Vec<u8>, Vec<u8>) {
    let source = std::fs::read(common::shared_data("rtcm").join("rtklib-testglo.rtcm3"))
        .expect("the stream");
    let mut frames = Vec::new();
    RtcmFramer::new().push(&source, |f, _| frames.push(f.to_vec()));
    assert!(frames.len() > 300, "{} frames", frames.len());
    let (mut served, mut expected) = (b"garbage before the first frame".to_vec(), Vec::new());
    for (i, frame) in frames.iter().enumerate() {
        if i % 7 == 3 {
            let mut bad = frame.clone();
            bad[5] ^= 0x5A;
            served.extend_from_slice(&bad);
        } else {
            served.extend_from_slice(frame);
            expected.extend_from_slice(frame);
        }
    }
    (served, expected)
}

/// Waits for `expected.len()` bytes at `port` (and a moment more, for any extra), stops the
/// daemon, checks the port got exactly `expected`, and returns the daemon's log.
fn stop_once_received(daemon: Proc, port: &PortReader, expected: &[u8]) -> Vec<String> {
    port.wait_len(expected.len(), WAIT);
    std::thread::sleep(Duration::from_millis(500));
    let log = daemon.stop_log();
    let got = port.bytes();
    assert!(
        got == expected,
        "{} of {} bytes\n{}",
        got.len(),
        expected.len(),
        log.join("\n")
    );
    log
}

/// Waits up to `wait` for 30 kB at `port`, stops the daemon, and checks they are whole valid
/// frames only, and one unbroken run of `stream` (the client joined it under way).
fn stop_with_a_run_of(daemon: Proc, port: &PortReader, stream: &[u8], wait: Duration) {
    let written = port.wait_len(30_000, wait);
    let log = daemon.stop_log();
    assert!(
        written.len() >= 30_000,
        "{} bytes at the receiver\n{}",
        written.len(),
        log.join("\n")
    );
    assert_eq!(
        valid_frames(&written),
        written,
        "bytes outside valid frames"
    );
    assert!(
        stream
            .windows(written.len())
            .any(|w| w == written.as_slice()),
        "not a run of the served stream"
    );
}

/// Checks an NMEA sentence's checksum.
fn valid_nmea(line: &str) -> bool {
    let Some(body) = line.strip_prefix('$') else {
        return false;
    };
    let Some((data, sum)) = body.split_once('*') else {
        return false;
    };
    let computed = data.bytes().fold(0u8, |a, b| a ^ b);
    u8::from_str_radix(sum, 16) == Ok(computed)
}

#[test]
fn corrupted_frames_never_reach_the_receiver_and_the_gga_goes_up_every_second() {
    let dir = common::tempdir("ntrip-corrupted");
    let (served, expected) = corrupted_stream();
    let caster = Caster::start(Behaviour::Stream {
        head: "ICY 200 OK\r\n\r\n".into(),
        body: served,
        chunks: vec![1, 700, 13, 255, 64, 1024, 3],
        every: Duration::from_millis(5),
        repeat: true,
    });
    let record = dir.join("recording");
    let (daemon, port, mut receiver) = run_with_caster(
        &dir,
        &format!(
            "url = \"{}\"\nversion = 1\ngga_interval_s = 1\nfallback_position = {{ lat = 48.1, lon = 11.5, height = 520 }}",
            caster.url()
        ),
        &["--record".as_ref(), record.as_os_str()],
    );
    // The receiver reports a fix: the GGA carries it once it has come.
    let started = Instant::now();
    let mut written = Vec::new();
    while started.elapsed() < WAIT {
        common::pty::send_on(
            &mut receiver,
            "GNGGA,120000.00,2308.98071170,N,11301.17918515,E,4,20,0.6,12.3,M,-6.1,M,1.0,0123",
        );
        written = port.bytes();
        if written.len() >= expected.len() {
            break;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(Duration::from_secs(3));
    let log = daemon.stop_log();
    let written_now = port.bytes();
    assert!(written_now.len() >= written.len());
    assert_eq!(
        written_now.len(),
        expected.len(),
        "the receiver got {} bytes, the valid frames are {}\n{}",
        written_now.len(),
        expected.len(),
        log.join("\n")
    );
    assert!(
        written_now == expected,
        "the bytes differ from the valid frames"
    );
    // One connection; the GGAs: valid sentences, the first within a second of the 200,
    // then one a second; the fallback first, the receiver's fix once it has one.
    let connections = caster.connections();
    assert_eq!(connections.len(), 1, "{connections:?}");
    let c = &connections[0];
    assert!(
        c.request.starts_with("GET /MOUNT HTTP/1.0\r\n"),
        "{}",
        c.request
    );
    assert!(
        c.request.contains("Authorization: Basic cm92ZXI6czNjcmV0"),
        "{}",
        c.request
    );
    let ggas: Vec<&(Instant, String)> = c.lines.iter().filter(|(_, l)| l.contains("GGA")).collect();
    assert!(ggas.len() >= 3, "{:?}", c.lines);
    assert!(ggas.iter().all(|(_, l)| valid_nmea(l)), "{ggas:?}");
    assert!(
        ggas[0].0.duration_since(c.at) < Duration::from_secs(1),
        "first GGA late"
    );
    for pair in ggas.windows(2) {
        let gap = pair[1].0.duration_since(pair[0].0).as_secs_f64();
        assert!((0.8..=1.3).contains(&gap), "GGA gap {gap} s: {ggas:?}");
    }
    assert!(
        ggas.iter().any(|(_, l)| l.contains("2308.98")),
        "the receiver's fix: {ggas:?}"
    );
    // The password is in no log line and nowhere in the recording.
    assert!(
        !log.iter().any(|l| l.contains("s3cret")),
        "password in the log"
    );
    for entry in std::fs::read_dir(&record).expect("recording") {
        let bytes = std::fs::read(entry.expect("entry").path()).expect("file");
        assert!(
            !bytes.windows(6).any(|w| w == b"s3cret"),
            "password in the recording"
        );
    }
    // The replay writes what the receiver got.
    let out = dir.join("replayed.rtcm");
    let replay = std::process::Command::new(common::chassisd())
        .arg("replay")
        .arg(&record)
        .arg("--corrections-out")
        .arg(&out)
        .output()
        .expect("replay runs");
    assert!(
        replay.status.success(),
        "{}",
        String::from_utf8_lossy(&replay.stderr)
    );
    let summary = String::from_utf8_lossy(&replay.stderr);
    assert!(summary.contains("corrections:"), "{summary}");
    assert!(
        std::fs::read(&out).expect("replayed corrections") == written_now,
        "{summary}"
    );
}

#[test]
fn a_chunked_ntrip_2_stream_arrives_de_chunked_and_whole() {
    let dir = common::tempdir("ntrip-chunked");
    let body = std::fs::read(common::shared_data("rtcm").join("pygnssutils-ntrip_chunked.bin"))
        .expect("the chunked capture");
    let mut plain = Vec::new();
    Dechunker::new()
        .push(&body, &mut plain)
        .expect("the capture de-chunks");
    let expected = valid_frames(&plain);
    assert!(expected.len() > 1000);
    let caster = Caster::start(Behaviour::Stream {
        // pygnssutils' malformed status line, as its caster sends it.
        head: "HTTP/1.1 200 OKNtrip-Version: Ntrip/2.0\r\nTransfer-Encoding: chunked\r\n\r\n"
            .into(),
        body,
        chunks: vec![17, 333, 1, 90],
        every: Duration::from_millis(5),
        repeat: true,
    });
    let (daemon, port, _receiver) = run_with_caster(
        &dir,
        &format!(
            "url = \"{}\"\ngga_interval_s = 0\nfallback_position = {{ lat = 48.1, lon = 11.5, height = 520 }}",
            caster.url()
        ),
        &[],
    );
    let log = stop_once_received(daemon, &port, &expected);
    // With gga_interval_s = 0 the client read the table first; it says MOUNT wants GGA
    // (nmea=1), so the GGA goes up all the same, the fallback position at once.
    let connections = caster.connections();
    assert!(
        connections[0].request.starts_with("GET / HTTP/1.1\r\n"),
        "{connections:?}"
    );
    let c = connections
        .iter()
        .find(|c| c.request.starts_with("GET /MOUNT HTTP/1.1\r\n"))
        .expect("the stream's request");
    assert!(
        c.request.contains("Ntrip-Version: Ntrip/2.0"),
        "{}",
        c.request
    );
    assert!(
        c.lines
            .first()
            .is_some_and(|(at, l)| l.contains("4806.000")
                && at.duration_since(c.at) < Duration::from_secs(1)),
        "the table's GGA flag honoured: {:?}",
        c.lines
    );
    assert!(
        log.iter()
            .any(|l| l.contains("needs the rover's position (nmea=1)")),
        "{log:#?}"
    );
}

#[test]
fn a_caster_that_closes_at_once_is_not_stormed() {
    let dir = common::tempdir("ntrip-storm");
    let caster = Caster::start(Behaviour::Close);
    let (daemon, port, _receiver) =
        run_with_caster(&dir, &format!("url = \"{}\"", caster.url()), &[]);
    std::thread::sleep(Duration::from_secs(25));
    let log = daemon.stop_log();
    let connects = caster.connections();
    // 10 s, then 20 s: connects at 0, 10 and 30 s.
    assert_eq!(connects.len(), 2, "connects in 25 s\n{}", log.join("\n"));
    let gap = connects[1].at.duration_since(connects[0].at).as_secs_f64();
    assert!(gap >= 9.5, "reconnected after {gap} s");
    assert!(port.bytes().is_empty());
    assert!(
        log.iter().any(|l| l.contains("NTRIP connection ended")),
        "{log:#?}"
    );
}

#[test]
fn a_caster_that_goes_silent_after_its_200_is_dropped_after_timeout_s() {
    let dir = common::tempdir("ntrip-silent");
    let caster = Caster::start(Behaviour::Silent {
        head: "ICY 200 OK\r\n\r\n".into(),
    });
    let (mut daemon, _port, _receiver) = run_with_caster(
        &dir,
        &format!("url = \"{}\"\ntimeout_s = 2", caster.url()),
        &[],
    );
    daemon.wait_log(WAIT, "no valid RTCM 3 frame for 2 s");
    let connects = caster.wait_connections(2, Duration::from_secs(20));
    // Said in the same instant as the drop, in either order.
    daemon.wait_log_seen(WAIT, "RTK corrections not arriving");
    let log = daemon.stop_log();
    assert!(connects.len() >= 2, "{}", log.join("\n"));
    // Dropped after 2 s of silence, then the back-off's 10 s.
    let gap = connects[1].at.duration_since(connects[0].at).as_secs_f64();
    assert!((11.0..=15.0).contains(&gap), "reconnected after {gap} s");
}

#[test]
fn refused_credentials_are_reported_with_the_fix_and_retried_slowly() {
    let dir = common::tempdir("ntrip-401");
    let caster = Caster::start(Behaviour::Unauthorized);
    // `--ntrip URL` overrides the configuration's caster (an address nobody answers on).
    let url = caster.url();
    let (mut daemon, port, _receiver) = run_with_caster(
        &dir,
        "url = \"ntrip://nobody@192.0.2.1:2101/ELSEWHERE\"",
        &["--ntrip".as_ref(), url.as_ref()],
    );
    daemon.wait_log(
        WAIT,
        "the caster refused the credentials (401 Unauthorized): check the user and the password",
    );
    let connects = caster.wait_connections(2, Duration::from_secs(15));
    let log = daemon.stop_log();
    assert!(connects.len() >= 2, "{}", log.join("\n"));
    let gap = connects[1].at.duration_since(connects[0].at).as_secs_f64();
    assert!(gap >= 9.5, "retried after {gap} s");
    assert!(port.bytes().is_empty());
    assert!(
        !log.iter().any(|l| l.contains("s3cret")),
        "password in the log"
    );
}

/// The RTK status (`rtk.status`, the GGA quality digit) of a base_status line.
fn rtk_status(line: &str) -> Option<u64> {
    serde_json::from_str::<serde_json::Value>(line)
        .ok()?
        .get("rtk")?
        .get("status")?
        .as_u64()
}

#[test]
fn the_simulated_receiver_holds_rtk_fixed_only_while_corrections_arrive() {
    // About 5 s of a reference station's frames, then silence with the connection open.
    let (served, _) = corrupted_stream();
    let caster = Caster::start(Behaviour::Stream {
        head: "ICY 200 OK\r\n\r\n".into(),
        body: served[..12_000].to_vec(),
        chunks: vec![120],
        every: Duration::from_millis(50),
        repeat: false,
    });
    let mut sim = Proc::start(&["sim", "--no-mqtt", "--ntrip", &caster.url()]);
    let started = Instant::now();
    // Before the first frame: DGPS; with corrections: RTK fixed; 10 s after the last:
    // float; 20 s later: DGPS again.
    let mut seen: Vec<(f64, u64)> = Vec::new();
    while started.elapsed() < Duration::from_secs(45) {
        for line in sim.drain_out().to_vec() {
            // 0 until the receiver's first fix.
            if let Some(q) = rtk_status(&line).filter(|&q| q != 0)
                && seen.last().is_none_or(|(_, last)| *last != q)
            {
                seen.push((started.elapsed().as_secs_f64(), q));
            }
        }
        if seen
            .iter()
            .map(|(_, q)| *q)
            .collect::<Vec<_>>()
            .ends_with(&[4, 5, 2])
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let log = sim.stop_log();
    // The caster starts at once, so its first frame can beat the receiver's first fix: then
    // no DGPS is seen before RTK fixed.
    if seen.first().is_some_and(|(_, q)| *q == 2) {
        seen.remove(0);
    }
    let order: Vec<u64> = seen.iter().map(|(_, q)| *q).collect();
    assert_eq!(order, [4, 5, 2], "{seen:?}\n{}", log.join("\n"));
    // Fixed for the ~5 s of frames and the 10 s after; float for 20 s.
    let fixed = seen[1].0 - seen[0].0;
    let float = seen[2].0 - seen[1].0;
    assert!(
        (12.0..=18.0).contains(&fixed),
        "fixed for {fixed} s: {seen:?}"
    );
    assert!(
        (18.0..=22.0).contains(&float),
        "float for {float} s: {seen:?}"
    );
    assert!(
        log.iter().any(|l| l.contains("RTK corrections stopped")),
        "{log:#?}"
    );
}

/// A child process killed when the test ends.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn pygnssutils_gnssserver_an_ntrip_2_caster_feeds_the_receiver_its_frames_in_order() {
    let dir = common::tempdir("ntrip-gnssserver");
    let source = std::fs::read(common::shared_data("rtcm").join("rtklib-GMSD7_20121014.rtcm3"))
        .expect("the stream");
    // gnssserver reads its input from a socket: the reference station's stream, paced.
    let feed = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let feed_port = feed.local_addr().expect("address").port();
    let paced = source.clone();
    std::thread::spawn(move || {
        use std::io::Write;
        if let Ok((mut s, _)) = feed.accept() {
            for chunk in paced.chunks(1500) {
                if s.write_all(chunk).is_err() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            std::thread::sleep(Duration::from_secs(120));
        }
    });
    let caster_port = common::mqtt::free_port();
    let gnssserver = common::repo().join("target/test-venv/bin/gnssserver");
    let _caster = Child(
        std::process::Command::new(&gnssserver)
            .args(["-S", &format!("127.0.0.1:{feed_port}"), "-N", "1"])
            .args(["--ntripversion", "2.0", "-H", "127.0.0.1"])
            .args(["-O", &caster_port.to_string()])
            .args([
                "--ntripuser",
                "rover",
                "--ntrippassword",
                "s3cret",
                "--verbosity",
                "0",
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "{} (tests/install-deps installs it): {e}",
                    gnssserver.display()
                )
            }),
    );
    // Its caster listens once it has started (Python takes a moment).
    let until = Instant::now() + Duration::from_secs(15);
    while std::net::TcpStream::connect(("127.0.0.1", caster_port)).is_err() {
        assert!(Instant::now() < until, "gnssserver does not listen");
        std::thread::sleep(Duration::from_millis(100));
    }
    // gnssserver's one mountpoint is `pygnssutils`.
    let (daemon, port, _receiver) = run_with_caster(
        &dir,
        &format!(
            "url = \"ntrip://rover:s3cret@127.0.0.1:{caster_port}/pygnssutils\"\nversion = 2\n\
             gga_interval_s = 1\nfallback_position = {{ lat = 48.1, lon = 11.5, height = 520 }}"
        ),
        &[],
    );
    stop_with_a_run_of(daemon, &port, &source, Duration::from_secs(40));
}

#[test]
fn an_ntrips_caster_is_checked_against_its_authority_and_streams_over_tls() {
    let dir = common::tempdir("ntrip-tls");
    let pki = common::mqtt::TestPki::create(&dir, "caster");
    let (served, expected) = corrupted_stream();
    let caster = Caster::start_tls(
        Behaviour::Stream {
            head: "HTTP/1.1 200 OK\r\n\r\n".into(),
            body: served,
            chunks: vec![900, 7, 333],
            every: Duration::from_millis(5),
            repeat: true,
        },
        &pki.cert,
        &pki.key,
    );
    let url = caster.url().replace("ntrip://", "ntrips://");
    // Without the caster's authority the handshake fails, and says what to do.
    let untrusted = common::tempdir("ntrip-tls-untrusted");
    let (mut refused, port, _receiver) =
        run_with_caster(&untrusted, &format!("url = \"{url}\""), &[]);
    refused.wait_log(
        WAIT,
        "is its certificate's authority trusted, or named as ntrip.ca_file?",
    );
    refused.stop_log();
    assert!(port.bytes().is_empty());
    // With it, the stream's valid frames arrive over TLS.
    let (daemon, port, _receiver) = run_with_caster(
        &dir,
        &format!("url = \"{url}\"\nca_file = \"{}\"", pki.ca.display()),
        &[],
    );
    stop_once_received(daemon, &port, &expected);
}

#[test]
fn the_ntrip_command_names_its_own_ca_file_option() {
    let dir = common::tempdir("ntrip-cli-tls");
    let pki = common::mqtt::TestPki::create(&dir, "caster");
    let (served, expected) = corrupted_stream();
    let caster = Caster::start_tls(
        Behaviour::Stream {
            head: "HTTP/1.1 200 OK\r\n\r\n".into(),
            body: served,
            chunks: vec![900],
            every: Duration::from_millis(5),
            repeat: true,
        },
        &pki.cert,
        &pki.key,
    );
    let url = caster.url().replace("ntrip://", "ntrips://");
    let out = dir.join("out.rtcm");
    let ntrip = |extra: &[&std::ffi::OsStr]| {
        let mut command = std::process::Command::new(common::chassisd());
        command.args(["ntrip", &url, "--duration", "2", "--out"]);
        command.arg(&out).args(extra);
        command.output().expect("chassisd ntrip runs")
    };
    let stderr = |o: &std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    // A file that is not there is named as the option that named it.
    let missing = ntrip(&["--ca-file".as_ref(), "/nonexistent/ca.pem".as_ref()]);
    assert!(!missing.status.success());
    assert!(
        stderr(&missing).contains("--ca-file /nonexistent/ca.pem: cannot read"),
        "{}",
        stderr(&missing)
    );
    // An authority not trusted: the advice names the option, not the configuration's key.
    let untrusted = ntrip(&[]);
    assert!(
        stderr(&untrusted).contains("or named as --ca-file?")
            && !stderr(&untrusted).contains("ntrip.ca_file"),
        "{}",
        stderr(&untrusted)
    );
    // Following it works.
    let trusted = ntrip(&["--ca-file".as_ref(), pki.ca.as_os_str()]);
    assert!(trusted.status.success(), "{}", stderr(&trusted));
    let written = std::fs::read(&out).expect("the output file");
    // The caster's valid frames from the start of its stream.
    let n = written.len().min(expected.len());
    assert!(
        n > 0 && written[..n] == expected[..n],
        "{} bytes written: {}",
        written.len(),
        stderr(&trusted)
    );
}

#[test]
fn a_receiver_that_takes_no_corrections_never_holds_up_its_fixes() {
    let dir = common::tempdir("ntrip-stalled");
    let (served, _) = corrupted_stream();
    // Far more than the pty's buffer, fast.
    let caster = Caster::start(Behaviour::Stream {
        head: "ICY 200 OK\r\n\r\n".into(),
        body: served.repeat(20),
        chunks: vec![4096],
        every: Duration::from_millis(2),
        repeat: true,
    });
    // The pty's master is never read: the receiver's port takes nothing once its buffer is
    // full, and the corrections' writes wait there.
    let (mut daemon, mut receiver) = run_with_receiver(
        &dir,
        &format!("url = \"{}\"\nqueue_frames = 16", caster.url()),
        &[],
    );
    daemon.wait_log(WAIT, "RTCM corrections dropped");
    // Fixes still arrive and are decoded: each new latitude shows in the status.
    for minutes in ["08.10000000", "08.20000000", "08.30000000"] {
        let lat = 23.0 + minutes.parse::<f64>().expect("minutes") / 60.0;
        let until = Instant::now() + Duration::from_secs(5);
        let mut seen = false;
        while !seen && Instant::now() < until {
            common::pty::send_on(
                &mut receiver,
                &format!(
                    "GNGGA,120000.00,23{minutes},N,11301.17918515,E,4,20,0.6,12.3,M,-6.1,M,1.0,0123"
                ),
            );
            std::thread::sleep(Duration::from_millis(100));
            seen = daemon.drain_out().iter().any(|l| {
                serde_json::from_str::<serde_json::Value>(l)
                    .ok()
                    .and_then(|s| s["rtk"]["latitude"].as_f64())
                    .is_some_and(|v| (v - lat).abs() < 1e-7)
            });
        }
        assert!(seen, "the fix at 23°{minutes}' never showed");
    }
    daemon.stop_log();
}

#[test]
fn with_ntrip_port_the_corrections_go_to_a_port_of_their_own() {
    let dir = common::tempdir("ntrip-port");
    let (served, expected) = corrupted_stream();
    let caster = Caster::start(Behaviour::Stream {
        head: "ICY 200 OK\r\n\r\n".into(),
        body: served,
        chunks: vec![256, 31],
        every: Duration::from_millis(5),
        repeat: true,
    });
    let second = dir.join("corrections");
    let corrections = {
        let _turn = one_at_a_time();
        PortReader::start(Port::open_at(&second).master)
    };
    let (daemon, receiver, _writer) = run_with_caster(
        &dir,
        &format!(
            "url = \"{}\"\nport = \"{}\"",
            caster.url(),
            second.display()
        ),
        &[],
    );
    stop_once_received(daemon, &corrections, &expected);
    assert!(receiver.bytes().is_empty(), "nothing to the NMEA port");
}

#[test]
fn rtklib_str2str_an_ntrip_1_caster_feeds_the_receiver_its_frames_in_order() {
    let dir = common::tempdir("ntrip-str2str-run");
    let source = common::shared_data("rtcm").join("rtklib-GMSD7_20121014.rtcm3");
    let stream = std::fs::read(&source).expect("the stream");
    // str2str's caster listens on every interface: it and chassisd share a network
    // namespace of their own. Its input is paced (a file would go out whole before any
    // client connects): 1,500 bytes every 100 ms. (Its output goes nowhere: chassisd's pipes
    // must close when chassisd ends.)
    let pacer = dir.join("pacer.py");
    std::fs::write(
        &pacer,
        "import sys,time\nd=open(sys.argv[1],'rb').read()\n\
         for i in range(0,len(d),1500):\n sys.stdout.buffer.write(d[i:i+1500]);sys.stdout.buffer.flush();time.sleep(0.1)\n\
         time.sleep(60)\n",
    )
    .expect("pacer");
    let script = format!(
        "ip link set lo up || exit 90\n\
         (timeout 90 python3 '{}' '{}' | timeout 90 str2str -out ntripc://rover:s3cret@:2101/MOUNT) \
         </dev/null >/dev/null 2>&1 &\n\
         sleep 1\n\
         exec \"$@\"\n",
        pacer.display(),
        source.display()
    );
    let link = dir.join("gnss");
    let config = dir.join("vehicle.toml");
    std::fs::write(
        &config,
        format!(
            "[gnss]\nport = \"{}\"\n\n[ntrip]\nurl = \"ntrip://rover:s3cret@127.0.0.1:2101/MOUNT\"\n\
             version = 1\ngga_interval_s = 1\nfallback_position = {{ lat = 48.1, lon = 11.5, height = 520 }}\n",
            link.display()
        ),
    )
    .expect("config");
    let (daemon, port) = {
        let _turn = one_at_a_time();
        let port = Port::open_at(&link);
        let daemon = Proc::start_under(
            &["unshare", "-rn", "sh", "-c", &script, "sh"],
            &["run".as_ref(), "--config".as_ref(), config.as_os_str()],
        );
        (daemon, PortReader::start(port.master))
    };
    stop_with_a_run_of(daemon, &port, &stream, Duration::from_secs(30));
}
