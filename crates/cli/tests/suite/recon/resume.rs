//! Resume: a finished or killed run continued from its work directory gives the same bytes.

use super::*;

#[test]
fn resume_gives_the_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    let ply = synth(d.path(), "bumpy", 30_000, 0.0);
    let a = d.path().join("a.ply");
    let b = d.path().join("b.ply");
    let work = d.path().join("w");
    recon(&ply, &a, &["--depth", "7"]);
    // A first run that keeps its work dir, then a resumed run reusing every leaf.
    recon(
        &ply,
        &b,
        &["--depth", "7", "--work-dir", s(&work), "--keep-work"],
    );
    std::fs::remove_file(&b).unwrap();
    let resumed = |progress| {
        [
            "reconstruct",
            s(&ply),
            "-o",
            s(&b),
            "--depth",
            "7",
            "--work-dir",
            s(&work),
            "--resume",
            "--progress",
            progress,
        ]
    };
    let o = run(&resumed("json"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("reconstructed"));
    // The coarse pass's results come back from its checkpoint: no point is read for it.
    assert!(
        err.contains("the coarse pass's results read back")
            && !err.contains("\"stage\":\"splat\"")
            && !err.contains("\"stage\":\"density\""),
        "{err}"
    );
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    // A corrupt coarse checkpoint is an error naming it, not a wrong mesh.
    recon(
        &ply,
        &b,
        &["--depth", "7", "--work-dir", s(&work), "--keep-work"],
    );
    let cp = work.join("leaves").join("coarse.zst");
    let good = std::fs::read(&cp).unwrap();
    std::fs::write(&cp, &good[..good.len() / 2]).unwrap();
    let err = fails(&resumed("none"));
    assert!(
        err.contains("coarse.zst") && err.contains("corrupt coarse checkpoint"),
        "{err}"
    );
    // Without --resume a used work dir is refused.
    let err = fails(&[
        "reconstruct",
        s(&ply),
        "-o",
        s(&d.path().join("c.ply")),
        "--work-dir",
        s(&work),
    ]);
    assert!(err.contains("another run"), "{err}");
}

#[test]
fn killed_run_resumes_to_the_same_bytes() {
    let d = tempfile::tempdir().unwrap();
    let ply = synth(d.path(), "bumpy", 200_000, 0.0005);
    let whole = d.path().join("whole.ply");
    recon(&ply, &whole, &["--depth", "8"]);
    // Kill (SIGKILL) once some leaves, then once some tiles, are checkpointed.
    for (phase, at) in [("leaves", 20), ("tiles", 4)] {
        let out = d.path().join(format!("resumed_{phase}.ply"));
        let work = d.path().join(format!("work_{phase}"));
        let mut child = bin()
            .args([
                "reconstruct",
                s(&ply),
                "-o",
                s(&out),
                "--depth",
                "8",
                "--work-dir",
                s(&work),
                "--progress",
                "none",
            ])
            .spawn()
            .unwrap();
        let dir = work.join(phase);
        let t0 = std::time::Instant::now();
        let mut killed = false;
        while t0.elapsed() < std::time::Duration::from_secs(120) {
            let n = std::fs::read_dir(&dir).map(|r| r.count()).unwrap_or(0);
            if n >= at {
                child.kill().unwrap();
                killed = true;
                break;
            }
            if child.try_wait().unwrap().is_some() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        let _ = child.wait();
        assert!(
            killed,
            "the run ended before it could be killed in the {phase} phase"
        );
        assert!(
            !out.exists(),
            "a killed run left a file under the final name"
        );
        let o = recon(
            &ply,
            &out,
            &["--depth", "8", "--work-dir", s(&work), "--resume"],
        );
        assert!(o.contains("reconstructed"), "{o}");
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&out).unwrap(),
            "{phase}"
        );
    }
}
