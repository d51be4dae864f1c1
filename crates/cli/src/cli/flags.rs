//! The command line's names for the library's settings.
//!
//! The library never spells a flag: a message that points at a setting names a
//! [`Setting`] (`` `work_dir` `` to a library caller). [`install`], which
//! [`Cli::parse_from_args`](crate::cli::args::Cli::parse_from_args) calls before clap parses
//! (so in `main` and in every test that parses), makes every message, log line and report
//! name them by the flags below instead, so a user reads `--work-dir`. The map is one exhaustive `match`: a setting added to the
//! library without a flag here does not compile, and a test checks that every flag it
//! names is one a command takes.

use scanflow::Setting;

/// The flag that sets `s`.
pub fn flag(s: Setting) -> &'static str {
    match s {
        Setting::Output => "-o",
        Setting::Mem => "--mem",
        Setting::WorkDir => "--work-dir",
        Setting::Resume => "--resume",
        Setting::Shard => "--shard",
        Setting::SkipInvalid => "--skip-invalid",
        Setting::Normals => "--normals",
        Setting::Neighbours => "--neighbours",
        Setting::RobustNormals => "--robust-normals",
        Setting::FixedNeighbours => "--fixed-neighbours",
        Setting::Viewpoint => "--viewpoint",
        Setting::MaxCellPoints => "--max-cell-points",
        Setting::ZstdLevel => "--zstd-level",
        Setting::Depth => "--depth",
        Setting::Smooth => "--smooth",
        Setting::PointWeight => "--point-weight",
        Setting::Error => "--error",
        Setting::MinPoints => "--min-points",
        Setting::Trim => "--trim",
        Setting::NoFit => "--no-fit",
        Setting::Gpu => "--gpu",
        Setting::GpuSolve => "--gpu-solve",
        Setting::Density => "--density",
        Setting::Confidence => "--confidence",
        Setting::SamplesPerNode => "--samples-per-node",
        Setting::TrimDensity => "--trim-density",
        Setting::TrimIslands => "--trim-islands",
        Setting::Tile => "--tile",
        Setting::Ascii => "--ascii",
        Setting::OutNormals => "--out-normals",
        Setting::Enhance => "--enhance",
        Setting::Bandstop => "--bandstop",
        Setting::Tolerance => "--tolerance",
        Setting::MaxLevel => "--max-level",
        Setting::Patches => "--patches",
        Setting::PatchPoints => "--patch-points",
        Setting::Tiles => "--tiles",
        Setting::Points => "--points",
        Setting::Noise => "--noise",
        Setting::Amplitude => "--amplitude",
        Setting::Frequency => "--frequency",
        Setting::TetSize => "--tet-size",
        Setting::Frames => "--frames",
        Setting::Scale => "--scale",
        Setting::KeepInverted => "--keep-inverted",
    }
}

/// Name every setting by its flag from now on (in messages, logs and reports).
pub fn install() {
    Setting::name_by(flag);
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use clap::CommandFactory;

    use super::*;
    use crate::cli::args::Cli;

    /// Every flag of every command, long (`--mem`) and short (`-o`).
    fn all_flags() -> BTreeSet<String> {
        fn walk(c: &clap::Command, out: &mut BTreeSet<String>) {
            for a in c.get_arguments() {
                out.extend(
                    a.get_long_and_visible_aliases()
                        .into_iter()
                        .flatten()
                        .map(|l| format!("--{l}")),
                );
                out.extend(a.get_short().map(|s| format!("-{s}")));
            }
            for s in c.get_subcommands() {
                walk(s, out);
            }
        }
        let mut out = BTreeSet::new();
        walk(&Cli::command(), &mut out);
        out
    }

    #[test]
    fn every_setting_is_a_flag_a_command_takes() {
        let flags = all_flags();
        let mut seen = BTreeSet::new();
        for &s in Setting::ALL {
            assert!(
                flags.contains(flag(s)),
                "{s:?} maps to {}, which no command takes",
                flag(s)
            );
            assert_eq!(Setting::from_name(s.name()), Some(s));
            assert!(seen.insert(flag(s)), "two settings map to {}", flag(s));
        }
    }

    /// The text of the string literals in `code` (Rust source with its comments and test
    /// modules removed), roughly: enough to find a flag spelled in a message.
    fn literals(code: &str) -> Vec<String> {
        let mut out = Vec::new();
        let mut chars = code.chars();
        let mut prev = ' ';
        while let Some(c) = chars.next() {
            if c == '\'' && prev != '\\' {
                // A char literal ('"' among them) or a lifetime: skip a quoted char.
                let mut look = chars.clone();
                match (look.next(), look.next(), look.next()) {
                    (Some('\\'), Some(_), Some('\'')) => {
                        chars.nth(2);
                    }
                    (Some(_), Some('\''), _) => {
                        chars.nth(1);
                    }
                    _ => {}
                }
            } else if c == '"' {
                let mut s = String::new();
                let mut escaped = false;
                for d in chars.by_ref() {
                    match (escaped, d) {
                        (false, '"') => break,
                        (false, '\\') => escaped = true,
                        _ => {
                            s.push(d);
                            escaped = false;
                        }
                    }
                }
                out.push(s);
            }
            prev = c;
        }
        out
    }

    /// `text` without its line comments and without the test module that ends a file.
    fn code_of(text: &str) -> String {
        let body = match text.find("#[cfg(test)]\nmod tests") {
            Some(i) => &text[..i],
            None => text,
        };
        body.lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// The boundary the issue asked for: only the command line names a flag. No string
    /// literal in a library crate's code (its tests aside) spells one of the command
    /// line's flags; messages name a [`Setting`] instead.
    #[test]
    fn no_library_message_spells_a_flag() {
        let flags: Vec<String> = all_flags()
            .into_iter()
            .filter(|f| f.starts_with("--"))
            .collect();
        let crates = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut found = Vec::new();
        let mut files = 0;
        let mut stack = vec![crates.clone()];
        while let Some(dir) = stack.pop() {
            for e in std::fs::read_dir(&dir).unwrap() {
                let p = e.unwrap().path();
                let rel = p
                    .strip_prefix(&crates)
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                if p.is_dir() {
                    let skip = rel == "cli" || rel.ends_with("/tests") || rel.ends_with("/benches");
                    if !skip {
                        stack.push(p);
                    }
                } else if rel.ends_with(".rs") && !rel.ends_with("tests.rs") {
                    files += 1;
                    let text = std::fs::read_to_string(&p).unwrap();
                    for lit in literals(&code_of(&text)) {
                        for f in &flags {
                            let spelled = lit.match_indices(f.as_str()).any(|(i, _)| {
                                !lit[i + f.len()..]
                                    .starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-')
                            });
                            if spelled {
                                found.push(format!("{rel}: {f} in {lit:?}"));
                            }
                        }
                    }
                }
            }
        }
        assert!(
            files > 100,
            "read only {files} library files from {}",
            crates.display()
        );
        assert!(
            found.is_empty(),
            "flags spelled outside the command line:\n{}",
            found.join("\n")
        );
    }

    #[test]
    fn installed_names_are_the_flags() {
        install();
        assert_eq!(Setting::WorkDir.to_string(), "--work-dir");
        assert_eq!(
            format!("raise {}", Setting::Mem),
            "raise --mem",
            "a library message reads as before"
        );
    }
}
