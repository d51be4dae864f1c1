use super::*;
use clap::CommandFactory;

#[test]
fn cli_is_consistent() {
    Cli::command().debug_assert();
}

fn choice_error(args: &[&str]) -> String {
    match Cli::parse_from_args(args) {
        Err(ParseError::Choice(m)) => m,
        Err(ParseError::Clap(e)) => panic!("{args:?}: clap error {e}"),
        Ok(c) => panic!("{args:?}: parsed {c:?}"),
    }
}

#[test]
fn bad_choices_keep_their_messages() {
    let m = choice_error(&["scanflow", "synth", "cube", "--points", "1", "-o", "x"]);
    assert_eq!(
        m,
        "unknown shape \"cube\": expected one of sphere, torus, twosheets, bumpy, heightfield"
    );
    let m = choice_error(&["scanflow", "reconstruct", "a", "-o", "b", "--gpu", "yes"]);
    assert_eq!(m, "--gpu \"yes\": expected one of auto, on, off");
    let m = choice_error(&["scanflow", "ingest", "a", "-o", "b", "--normals", "x"]);
    assert_eq!(m, "--normals \"x\": expected auto, use or estimate");
    let m = choice_error(&["scanflow", "info", "a", "--progress", "loud"]);
    assert_eq!(m, "--progress \"loud\": expected auto, bars, json or none");
}

#[test]
fn choices_map_onto_the_library() {
    let Ok(c) =
        Cli::parse_from_args(["scanflow", "synth", "TwoSheets", "--points", "1", "-o", "x"])
    else {
        panic!("synth TwoSheets parses");
    };
    let Cmd::Synth(a) = c.cmd else {
        panic!("synth")
    };
    assert_eq!(Shape::from(a.shape), Shape::TwoSheets);
    for shape in Shape::ALL {
        let c = ShapeChoice::from_str(shape.name(), false).map(Shape::from);
        assert_eq!(c, Ok(shape));
    }
    for mode in [GpuMode::Auto, GpuMode::On, GpuMode::Off] {
        let c = GpuChoice::from_str(&mode.to_string(), false).map(GpuMode::from);
        assert_eq!(c, Ok(mode));
    }
}

#[test]
fn help_states_the_code_s_numbers() {
    let mut cli = Cli::command();
    let help = cli
        .find_subcommand_mut("reconstruct")
        .and_then(|c| c.get_arguments().find(|a| a.get_id() == "neighbours"))
        .and_then(|a| a.get_help())
        .map(|h| h.to_string())
        .unwrap_or_default();
    let cap = format!("up to {} times", scanflow::normals::MAX_K_FACTOR);
    assert!(help.contains(&cap), "{help}");
}
