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
    let err = ok_log(&[
        "ingest",
        s(&xyz),
        "-o",
        s(&store),
        "--max-cell-points",
        "100",
        "--progress",
        "bars",
    ]);
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

/// The long options in `text`: `--name` tokens.
fn long_options(text: &str) -> std::collections::BTreeSet<String> {
    let mut out = std::collections::BTreeSet::new();
    let b = text.as_bytes();
    let mut i = 0;
    while i + 2 < b.len() {
        let starts =
            b[i] == b'-' && b[i + 1] == b'-' && (i == 0 || !b[i - 1].is_ascii_alphanumeric());
        if starts && b[i + 2].is_ascii_alphabetic() {
            let mut j = i + 2;
            while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'-') {
                j += 1;
            }
            out.insert(String::from_utf8_lossy(&b[i..j]).into_owned());
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// The long options a `--help` page defines: the first `--name` of each line that starts
/// with `--name` or `-x, --name`.
fn defined_options(help: &str) -> std::collections::BTreeSet<String> {
    help.lines()
        .filter_map(|l| {
            let t = l.trim_start();
            let t = match t.as_bytes() {
                [b'-', b'-', ..] => t,
                [b'-', c, b',', b' ', ..] if c.is_ascii_alphanumeric() => &t[4..],
                _ => return None,
            };
            long_options(t).into_iter().next()
        })
        .collect()
}

/// The README's command synopsis names every option each command takes and no other: each
/// command's lines are checked against its `--help` (the options every command takes are
/// stated once below the synopsis; `[SPECTRAL OPTIONS]` is spelled out under the spectral
/// commands; `-o` is `--output`).
#[test]
fn the_readme_synopsis_matches_every_command_help() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md")).unwrap();
    let block = readme
        .split("## Commands\n\n```sh\n")
        .nth(1)
        .and_then(|r| r.split("\n```").next())
        .expect("the README's command synopsis");
    let mut entries: Vec<(String, String)> = Vec::new();
    for line in block.lines() {
        match line.strip_prefix("scanflow ") {
            Some(rest) => {
                let cmd = rest.split_whitespace().next().unwrap().to_string();
                entries.push((cmd, rest.to_string()));
            }
            None => entries
                .last_mut()
                .expect("a command first")
                .1
                .push_str(line),
        }
    }
    let synopsis: std::collections::BTreeMap<String, String> = entries.into_iter().collect();
    let spectral = block
        .split("SPECTRAL OPTIONS:")
        .nth(1)
        .map(|r| r.split("\nscanflow ").next().unwrap_or(""))
        .expect("SPECTRAL OPTIONS spelled out");
    let common: std::collections::BTreeSet<String> =
        ["--threads", "--mem", "--progress", "--help", "--version"]
            .iter()
            .map(|s| s.to_string())
            .collect();
    let help_out = run(&["--help"]);
    let help = String::from_utf8_lossy(&help_out.stdout);
    let commands: Vec<String> = help
        .split("Commands:\n")
        .nth(1)
        .unwrap()
        .split("\n\n")
        .next()
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect();
    assert!(commands.len() > 10, "{commands:?}");
    let mut wrong = Vec::new();
    for cmd in &commands {
        let Some(text) = synopsis.get(cmd) else {
            wrong.push(format!("{cmd}: not in the README's synopsis"));
            continue;
        };
        let mut listed = long_options(text);
        if text.contains("[SPECTRAL OPTIONS]") {
            listed.extend(long_options(spectral));
        }
        if text.contains("-o ") {
            listed.insert("--output".to_string());
        }
        let o = run(&[cmd, "--help"]);
        let options: std::collections::BTreeSet<String> =
            defined_options(&String::from_utf8_lossy(&o.stdout))
                .difference(&common)
                .cloned()
                .collect();
        for missing in options.difference(&listed) {
            wrong.push(format!("{cmd}: {missing} is not in the README's synopsis"));
        }
        for extra in listed.difference(&options) {
            // PoissonRecon's names, accepted as hidden aliases.
            if !["--pointWeight", "--samplesPerNode", "--aRatio"].contains(&extra.as_str()) {
                wrong.push(format!(
                    "{cmd}: the README lists {extra}, which --help does not"
                ));
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// Shell completions and man pages come from the clap definitions.
#[test]
fn completions_and_man_pages_name_the_options() {
    let bash = ok(&["completions", "bash"]);
    assert!(
        bash.contains("_scanflow()") && bash.contains("--out-normals"),
        "{bash:.200}"
    );
    let fish = ok(&["completions", "fish"]);
    assert!(fish.contains("complete -c scanflow"), "{fish:.200}");
    let dir = tempfile::tempdir().unwrap();
    let man = dir.path().join("man1");
    ok(&["man", "-o", man.to_str().unwrap()]);
    let page = std::fs::read_to_string(man.join("scanflow-reconstruct.1")).unwrap();
    assert!(
        page.starts_with(".ie") || page.contains(".TH"),
        "{page:.200}"
    );
    assert!(page.contains("out\\-normals"), "{page:.400}");
    assert!(man.join("scanflow.1").exists());
    let file = dir.path().join("f");
    std::fs::write(&file, "").unwrap();
    let e = usage(&["man", "-o", file.to_str().unwrap()]);
    assert!(e.contains("not a directory"), "{e}");
    let o = run(&["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("possible values"));
}

/// Off a terminal (`--progress json`) every line carries an ISO 8601 time and the run ends
/// with one summary object holding its figures.
#[test]
fn json_progress_lines_are_timed_and_end_with_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let pts = scan(dir.path());
    let out = dir.path().join("m.ply");
    let o = run(&[
        "reconstruct",
        pts.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--depth",
        "6",
        "--progress",
        "json",
    ]);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<serde_json::Value> = err
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    assert!(lines.len() >= 4, "{err}");
    for l in &lines {
        let t = l["time"].as_str().unwrap_or_else(|| panic!("{l}"));
        assert!(
            t.len() == 24 && t.ends_with('Z') && t.as_bytes()[10] == b'T',
            "{t}"
        );
    }
    let last = lines.last().unwrap();
    assert_eq!(last["stage"], "summary", "{last}");
    assert_eq!(last["command"], "reconstruct");
    assert!(last["vertices"].as_u64().unwrap() > 0 && last["total_s"].as_f64().is_some());
}
