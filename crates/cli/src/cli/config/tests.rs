use super::*;
use clap::Parser;

fn config(args: &[&str]) -> Result<Config> {
    Config::new(Cli::try_parse_from(args)?)
}

fn err(args: &[&str]) -> String {
    match config(args) {
        Ok(_) => panic!("{args:?} accepted"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn points_parse() {
    assert_eq!(parse_point("1, 2.5,-3").ok(), Some([1.0, 2.5, -3.0]));
    for bad in ["", "1,2", "1,2,3,4", "1,x,3", "1,2,inf", "nan,0,0"] {
        assert!(parse_point(bad).is_err(), "{bad}");
    }
}

#[test]
fn bad_values_are_refused_before_any_work() {
    let r = ["scanflow", "reconstruct", "in.ply", "-o", "out.ply"];
    let with = |extra: &[&'static str]| [&r[..], extra].concat();
    assert!(err(&with(&["--smooth", "0"])).contains("--smooth 0"));
    assert!(err(&with(&["--smooth", "9"])).contains("(0, 8]"));
    assert!(err(&with(&["--error=-1"])).contains("--error -1"));
    assert!(err(&with(&["--depth", "30"])).contains("5..=13"));
    assert!(err(&with(&["--mem", "lots"])).contains("--mem \"lots\""));
    let e = err(&with(&["--viewpoint", "0,0,1", "--viewpoint", "1,0,0"]));
    assert!(e.contains("given 2 times for 1 input files"), "{e}");
    let i = ["scanflow", "ingest", "in.ply", "-o", "s.store"];
    let e = err(&[&i[..], &["--zstd-level", "20"]].concat());
    assert_eq!(e, "--zstd-level 20: expected -7 ..= 19");
    let e = err(&[&i[..], &["--viewpoint", "1,2"]].concat());
    assert!(e.contains("x,y,z"), "{e}");
}

#[test]
fn reconstruct_defaults() {
    let Ok(Config::Reconstruct(c)) = config(&["scanflow", "reconstruct", "a.ply", "-o", "m.ply"])
    else {
        panic!("reconstruct parses");
    };
    assert_eq!(c.params.run.work_dir, Path::new("m.ply.work"));
    assert_eq!(c.params.solve.depth, 9);
    assert_eq!(c.params.run.gpu, scanflow::extract::gpu::GpuMode::Off);
    assert!(c.params.mesh.fit && !c.params.mesh.trim && !c.keep_work);
    assert!(matches!(c.points, Points::Files(ref i, _) if i.files.len() == 1));
}
