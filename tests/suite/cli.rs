//! The command line itself: bad choice values, options checked before any work, log lines
//! with progress bars, help that states the code's numbers.

use super::common::*;

/// A small oriented scan in `dir`.
fn scan(dir: &std::path::Path) -> std::path::PathBuf {
    let ply = dir.join("s.ply");
    ok(&[
        "synth",
        "sphere",
        "--points",
        "2000",
        "-o",
        s(&ply),
        "--progress",
        "none",
    ]);
    ply
}

#[test]
fn bad_choice_values_are_usage_errors_with_status_2() {
    let d = tempfile::tempdir().unwrap();
    let ply = scan(d.path());
    let out = d.path().join("o.ply");
    let r = ["reconstruct", s(&ply), "-o", s(&out)];
    let err = usage(&[&r[..], &["--gpu", "yes"]].concat());
    assert!(
        err.contains("--gpu \"yes\": expected one of auto, on, off"),
        "{err}"
    );
    let err = usage(&[&r[..], &["--progress", "loud"]].concat());
    assert!(
        err.contains("--progress \"loud\": expected auto, bars, json or none"),
        "{err}"
    );
    let err = usage(&[&r[..], &["--normals", "maybe"]].concat());
    assert!(err.contains("auto, use or estimate"), "{err}");
    // Shapes ignore ASCII case, as they always did.
    let o = ok(&[
        "synth",
        "Torus",
        "--points",
        "100",
        "-o",
        s(&d.path().join("t.ply")),
        "--progress",
        "none",
    ]);
    assert!(o.starts_with("wrote 100 points of torus"), "{o}");
}

#[test]
fn options_are_checked_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let ply = scan(d.path());
    let out = d.path().join("o.ply");
    let work = d.path().join("o.ply.work");
    let r = ["reconstruct", s(&ply), "-o", s(&out), "--progress", "none"];
    for (bad, want) in [
        (&["--depth", "30"][..], "--depth 30"),
        (&["--smooth", "9"][..], "--smooth 9"),
        (&["--error=-1"][..], "--error -1"),
        (&["--point-weight=-1"][..], "--point-weight -1"),
        (&["--pointWeight", "100"][..], "--point-weight 100"),
        (
            &["--viewpoint", "1,2,3", "--viewpoint", "4,5,6"][..],
            "--viewpoint given 2 times",
        ),
        (&["--mem", "lots"][..], "--mem \"lots\""),
    ] {
        let err = usage(&[&r[..], bad].concat());
        assert!(err.contains(want), "{bad:?}: {err}");
        assert!(!work.exists(), "{bad:?}: the work directory was made");
        assert!(!out.exists(), "{bad:?}: an output appeared");
    }
    let st = d.path().join("s.store");
    let err = usage(&["ingest", s(&ply), "-o", s(&st), "--zstd-level", "20"]);
    assert!(err.contains("--zstd-level 20: expected -7 ..= 19"), "{err}");
    assert!(!st.exists());
}

#[test]
fn warnings_are_shown_with_bars() {
    // Off a terminal, bars draw nothing; the log line must still be written.
    let d = tempfile::tempdir().unwrap();
    let xyz = d.path().join("same.xyz");
    let mut text = String::from("10 10 10\n");
    text += &"1 2 3\n".repeat(300);
    std::fs::write(&xyz, text).unwrap();
    let store = d.path().join("same.store");
    let o = run(&[
        "ingest",
        s(&xyz),
        "-o",
        s(&store),
        "--max-cell-points",
        "100",
        "--progress",
        "bars",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("scanflow: warning: ") && err.contains("300 points within one finest cell"),
        "{err}"
    );
}

#[test]
fn help_states_the_code_s_defaults() {
    let help = ok(&["reconstruct", "--help"]);
    for want in [
        "default 64",
        "up to 8 times",
        "[default: 9]",
        "[default: off]",
    ] {
        assert!(
            help.contains(want),
            "reconstruct --help lacks \"{want}\":\n{help}"
        );
    }
    let help = ok(&["demo", "--help"]);
    assert!(
        help.contains("reconstruct") && help.contains("check"),
        "{help}"
    );
}
