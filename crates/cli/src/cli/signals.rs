//! SIGINT and SIGTERM: the temporary outputs are removed ([`atomic::remove_live_temps`]), the
//! work directory stays for `--resume`, the user is told so, and the process exits with
//! 128 + the signal's number (130, 143), as shells report a command killed by it.

use std::sync::Mutex;

use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;

use scanflow::fs::atomic;

use super::logger;

/// What the interrupt message adds (where the work directory is kept), set while a run has one.
static NOTE: Mutex<Option<String>> = Mutex::new(None);

/// Handle SIGINT and SIGTERM on a thread of their own. Without it (a platform without
/// signals) they end the process as the system's default does.
pub fn install() {
    let Ok(mut signals) = Signals::new([SIGINT, SIGTERM]) else {
        log::warn!("cannot handle SIGINT/SIGTERM: an interrupted run may leave temporary files");
        return;
    };
    let spawned = std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                atomic::remove_live_temps();
                let name = if sig == SIGINT { "SIGINT" } else { "SIGTERM" };
                let note = NOTE
                    .lock()
                    .map(|n| n.clone())
                    .unwrap_or_else(|p| p.into_inner().clone());
                let tail = note.map(|n| format!("; {n}")).unwrap_or_default();
                logger::eprintln(&format!(
                    "scanflow: interrupted by {name}: temporary files removed{tail}"
                ));
                std::process::exit(128 + sig);
            }
        });
    if spawned.is_err() {
        log::warn!("cannot handle SIGINT/SIGTERM: an interrupted run may leave temporary files");
    }
}

/// Say `note` when interrupted from now on (`None`: nothing more).
pub fn set_note(note: Option<String>) {
    match NOTE.lock() {
        Ok(mut n) => *n = note,
        Err(p) => *p.into_inner() = note,
    }
}
