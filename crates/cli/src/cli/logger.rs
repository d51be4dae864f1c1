//! The logger: `scanflow: LEVEL: message` on stderr, written through the progress reporter
//! so that a line never tears the bars (ARCHITECTURE.md step 2).

use std::sync::OnceLock;

use scanflow::exec::progress::Progress;

/// Logs at `info` and above; writes through the command's progress reporter once it has one.
struct Logger {
    progress: OnceLock<Progress>,
}

static LOGGER: Logger = Logger {
    progress: OnceLock::new(),
};

/// Install the logger (at `info`). A second call changes nothing.
pub fn install() {
    let _ = log::set_logger(&LOGGER).map(|()| log::set_max_level(log::LevelFilter::Info));
}

/// Route log lines (and [`eprintln!`]) through `progress` from now on: the command's one
/// reporter. Only the first call counts; a command makes one.
pub fn attach(progress: &Progress) {
    let _ = LOGGER.progress.set(progress.clone());
}

/// Write `line` to stderr, past the bars when they are shown.
pub fn eprintln(line: &str) {
    match LOGGER.progress.get() {
        Some(p) => p.eprintln(line),
        None => std::eprintln!("{line}"),
    }
}

impl log::Log for Logger {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Info
    }

    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            let level = match r.level() {
                log::Level::Error => "error",
                log::Level::Warn => "warning",
                _ => "info",
            };
            eprintln(&format!("scanflow: {level}: {}", r.args()));
        }
    }

    fn flush(&self) {}
}
