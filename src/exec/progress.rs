//! Progress: indicatif bars on a terminal, one JSON line per stage (and every few seconds)
//! on stderr otherwise, so that cluster logs stay machine-readable.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crossbeam_channel::{Sender, bounded};

/// Interval between a running stage's JSON lines (`--progress json`, and `auto` off a
/// terminal): often enough to show a cluster job is alive, rare enough to keep logs short.
pub const JSON_INTERVAL: Duration = Duration::from_secs(5);

/// How progress is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Bars on the terminal.
    Bars,
    /// JSON lines on stderr every `every` and at each stage's end.
    Json {
        /// Interval between lines while a stage runs.
        every: Duration,
    },
    /// Nothing (library use, tests).
    Quiet,
}

impl Mode {
    /// Bars when stderr is a terminal, JSON lines every 5 s otherwise.
    pub fn detect() -> Mode {
        use std::io::IsTerminal;
        if std::io::stderr().is_terminal() {
            Mode::Bars
        } else {
            Mode::Json {
                every: JSON_INTERVAL,
            }
        }
    }
}

/// The progress reporter of one command.
#[derive(Debug, Clone)]
pub struct Progress {
    mode: Mode,
    multi: Option<indicatif::MultiProgress>,
}

impl Progress {
    /// A reporter in `mode`.
    pub fn new(mode: Mode) -> Progress {
        let multi = (mode == Mode::Bars).then(indicatif::MultiProgress::new);
        Progress { mode, multi }
    }

    /// A reporter that shows nothing.
    pub fn quiet() -> Progress {
        Progress::new(Mode::Quiet)
    }

    /// Run `f` with bars hidden, so that a log line is not torn by a redraw.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        match &self.multi {
            Some(m) => m.suspend(f),
            None => f(),
        }
    }

    /// Write `line` to stderr; with bars shown, the bars are hidden while it is written and
    /// redrawn below it, so neither is torn. Log lines and error messages go through here.
    pub fn eprintln(&self, line: &str) {
        self.suspend(|| eprintln!("{line}"));
    }

    /// Start a stage counting `unit`s (`points`, `cells`) up to `total` when known.
    pub fn stage(&self, name: &str, total: Option<u64>, unit: &'static str) -> Stage {
        let done = Arc::new(AtomicU64::new(0));
        let start = Instant::now();
        let mut bar = None;
        let mut ticker = None;
        match (self.mode, &self.multi) {
            (Mode::Bars, Some(m)) => {
                let b = match total {
                    Some(t) => indicatif::ProgressBar::new(t),
                    None => indicatif::ProgressBar::new_spinner(),
                };
                let style = indicatif::ProgressStyle::with_template(&format!(
                    "{{prefix:>8}} [{{bar:30}}] {{human_pos}}/{{human_len}} {unit} {{per_sec}} eta {{eta}}"
                ))
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> ");
                b.set_style(style);
                b.set_prefix(name.to_string());
                bar = Some(m.add(b));
            }
            (Mode::Json { every }, _) => {
                let (tx, rx) = bounded::<()>(0);
                let d = Arc::clone(&done);
                let n = name.to_string();
                let h = std::thread::spawn(move || {
                    while let Err(crossbeam_channel::RecvTimeoutError::Timeout) =
                        rx.recv_timeout(every)
                    {
                        emit(
                            &n,
                            "running",
                            d.load(Ordering::Relaxed),
                            total,
                            unit,
                            start,
                            None,
                        );
                    }
                });
                ticker = Some((tx, h));
            }
            _ => {}
        }
        Stage {
            name: name.to_string(),
            unit,
            total,
            done,
            start,
            bar,
            ticker,
            json: matches!(self.mode, Mode::Json { .. }),
        }
    }
}

/// One stage's counter.
#[derive(Debug)]
pub struct Stage {
    name: String,
    unit: &'static str,
    total: Option<u64>,
    done: Arc<AtomicU64>,
    start: Instant,
    bar: Option<indicatif::ProgressBar>,
    ticker: Option<(Sender<()>, std::thread::JoinHandle<()>)>,
    json: bool,
}

impl Stage {
    /// Count `n` more units done. Cheap; call per chunk, not per point.
    pub fn inc(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }

    /// Units done so far.
    pub fn done(&self) -> u64 {
        self.done.load(Ordering::Relaxed)
    }

    /// End the stage; `extra` fields go into its JSON line.
    pub fn finish(mut self, extra: Option<serde_json::Value>) {
        self.stop();
        if self.json {
            emit(
                &self.name,
                "done",
                self.done(),
                self.total,
                self.unit,
                self.start,
                extra,
            );
        }
    }

    fn stop(&mut self) {
        if let Some((tx, h)) = self.ticker.take() {
            drop(tx);
            let _ = h.join();
        }
        if let Some(b) = self.bar.take() {
            b.finish();
        }
    }
}

impl Drop for Stage {
    fn drop(&mut self) {
        self.stop();
    }
}

fn emit(
    name: &str,
    state: &str,
    done: u64,
    total: Option<u64>,
    unit: &str,
    start: Instant,
    extra: Option<serde_json::Value>,
) {
    let secs = start.elapsed().as_secs_f64();
    let mut v = serde_json::json!({
        "stage": name,
        "state": state,
        "done": done,
        "total": total,
        "unit": unit,
        "elapsed_s": (secs * 1000.0).round() / 1000.0,
        "per_s": if secs > 0.0 { (done as f64 / secs).round() } else { 0.0 },
        "peak_rss_bytes": crate::exec::peak_rss_bytes(),
    });
    if let (Some(serde_json::Value::Object(m)), Some(o)) = (extra, v.as_object_mut()) {
        o.extend(m);
    }
    eprintln!("{v}");
}
