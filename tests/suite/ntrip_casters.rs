//! chassisd's NTRIP client (`chassisd ntrip`) against a real caster: RTKLIB's str2str serving
//! a real reference station's stream (`../shared/data/rtcm/rtklib-GMSD7_20121014.rtcm3`),
//! paced as a base station sends it. The caster and the client run in a network namespace of
//! their own (str2str's caster listens on every interface), so nothing else can reach it.
//! What the client writes must be the caster's valid frames, whole and in order.

use crate::common;

use std::process::Command;

/// Serves `file` through str2str on 127.0.0.1:2101/MOUNT (user `rover`, password `s3cret`)
/// and runs `chassisd ntrip` with `client_args` for `seconds`; returns its stderr and what it
/// wrote.
fn through_str2str(file: &str, client_args: &str, seconds: u32) -> (String, Vec<u8>) {
    let dir = common::tempdir("ntrip-str2str");
    let out = dir.join("out.rtcm");
    let source = common::shared_data("rtcm").join(file);
    // One chunk of 1,500 bytes every 100 ms (str2str would send a file given as -in whole
    // before any client connects).
    let pacer = "import sys,time\n\
                 d=open(sys.argv[1],'rb').read()\n\
                 for i in range(0,len(d),1500):\n \
                 sys.stdout.buffer.write(d[i:i+1500]);sys.stdout.buffer.flush();time.sleep(0.1)\n\
                 time.sleep(60)\n";
    let script = format!(
        "ip link set lo up || exit 90\n\
         (timeout {caster} python3 -c \"$PACER\" '{source}' | timeout {caster} str2str \
           -out ntripc://rover:s3cret@:2101/MOUNT 2>'{log}') &\n\
         sleep 1\n\
         '{chassisd}' ntrip ntrip://rover:s3cret@127.0.0.1:2101/MOUNT --out '{out}' \
           --duration {seconds} {client_args}\n\
         status=$?\n\
         kill %1 2>/dev/null\n\
         exit $status\n",
        caster = seconds + 5,
        source = source.display(),
        log = dir.join("str2str.log").display(),
        chassisd = common::chassisd().display(),
        out = out.display(),
    );
    let o = Command::new("unshare")
        .args(["-rn", "sh", "-c", &script])
        .env("PACER", pacer)
        .output()
        .expect("unshare runs (util-linux)");
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        o.status.success(),
        "chassisd ntrip against str2str failed ({:?}):\n{stderr}\nstr2str: {}",
        o.status.code(),
        std::fs::read_to_string(dir.join("str2str.log")).unwrap_or_default()
    );
    (stderr, std::fs::read(&out).expect("the output file"))
}

#[test]
fn a_real_caster_s_frames_arrive_whole_and_in_order() {
    let (report, written) = through_str2str(
        "rtklib-GMSD7_20121014.rtcm3",
        "--version 2 --position 48.1,11.5,520 --gga-interval 1",
        6,
    );
    let source = std::fs::read(common::shared_data("rtcm").join("rtklib-GMSD7_20121014.rtcm3"))
        .expect("the stream");
    // str2str answers a 2.0 request as a 1.0 caster; the client joins mid-stream, so what it
    // wrote is one unbroken run of the source's frames.
    assert!(
        written.len() > 20_000,
        "only {} bytes:\n{report}",
        written.len()
    );
    assert!(
        source
            .windows(written.len())
            .any(|w| w == written.as_slice()),
        "the written bytes are not a run of the caster's stream:\n{report}"
    );
    let json: serde_json::Value = serde_json::from_str(report.lines().last().unwrap_or_default())
        .expect("the report's last line is JSON");
    assert_eq!(json["attempts"], 1, "{report}");
    assert!(json["ggas_sent"].as_u64().unwrap_or(0) >= 5, "{report}");
    for t in ["1077", "1087", "1127"] {
        assert!(json["by_type"][t].as_u64().unwrap_or(0) > 0, "{report}");
    }
    // The password never shows.
    assert!(!report.contains("s3cret"), "{report}");
}

#[test]
fn a_wrong_mountpoint_names_the_ones_the_caster_has() {
    let dir = common::tempdir("ntrip-mount");
    let out = dir.join("out.rtcm");
    let script = format!(
        "ip link set lo up || exit 90\n\
         (sleep 30 | timeout 12 str2str -out ntripc://rover:s3cret@:2101/MOUNT 2>/dev/null) &\n\
         sleep 1\n\
         '{chassisd}' ntrip ntrip://rover:s3cret@127.0.0.1:2101/NOPE --version 1 --out '{out}' \
           --duration 4\n\
         status=$?\n\
         kill %1 2>/dev/null\n\
         exit $status\n",
        chassisd = common::chassisd().display(),
        out = out.display(),
    );
    let o = Command::new("unshare")
        .args(["-rn", "sh", "-c", &script])
        .output()
        .expect("unshare runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    // Nothing arrived: exit 1, and the reason names the caster's mountpoint.
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("no mountpoint \\\"NOPE\\\"") || stderr.contains("no mountpoint \"NOPE\""),
        "{stderr}"
    );
    assert!(stderr.contains("MOUNT"), "{stderr}");
}
