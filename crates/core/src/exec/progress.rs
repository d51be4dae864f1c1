//! Progress: indicatif bars on a terminal, one JSON line per stage (and every few seconds)
//! on stderr otherwise, so that cluster logs stay machine-readable.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use crossbeam_channel::{Sender, bounded};
use serde::Serialize;

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

/// A finished stage, as the run report lists it.
#[derive(Debug, Clone, Serialize)]
pub struct StageRecord {
    /// The stage's name (`ingest`, `leaves`, `tiles`, …).
    pub name: String,
    /// What it counted.
    pub unit: String,
    /// Units done.
    pub done: u64,
    /// Units expected, when known.
    pub total: Option<u64>,
    /// Seconds from its start to its end.
    pub secs: f64,
    /// Seconds from the reporter's creation to the stage's start.
    pub start_secs: f64,
    /// The process's peak resident memory at its end, in bytes.
    pub peak_rss_bytes: u64,
}

/// The progress reporter of one command.
#[derive(Debug, Clone)]
pub struct Progress {
    mode: Mode,
    multi: Option<indicatif::MultiProgress>,
    /// Every finished stage, in order of finishing.
    records: Arc<Mutex<Vec<StageRecord>>>,
    /// Stages started so far: the next stage's ordinal.
    started: Arc<AtomicU64>,
    created: Instant,
}

impl Progress {
    /// A reporter in `mode`.
    pub fn new(mode: Mode) -> Progress {
        let multi = (mode == Mode::Bars).then(indicatif::MultiProgress::new);
        Progress {
            mode,
            multi,
            records: Arc::default(),
            started: Arc::default(),
            created: Instant::now(),
        }
    }

    /// With JSON progress (off a terminal), write the command's final summary as one JSON
    /// line on stderr: `{"time", "stage": "summary", "command", "total_s", ...fields}`, so a
    /// cluster log ends with the run's figures in the same form as its progress. Nothing in
    /// the other modes (the printed summary is the terminal's).
    pub fn summary(&self, command: &str, total_secs: f64, fields: &serde_json::Value) {
        if !matches!(self.mode, Mode::Json { .. }) {
            return;
        }
        let mut v = serde_json::json!({
            "time": timestamp(SystemTime::now()),
            "stage": "summary",
            "command": command,
            "total_s": (total_secs * 1000.0).round() / 1000.0,
            "peak_rss_bytes": crate::exec::peak_rss_bytes(),
        });
        if let (Some(o), serde_json::Value::Object(f)) = (v.as_object_mut(), fields) {
            for (k, x) in f {
                o.entry(k.clone()).or_insert_with(|| x.clone());
            }
        }
        self.eprintln(&v.to_string());
    }

    /// The stages finished so far, in order of finishing.
    pub fn records(&self) -> Vec<StageRecord> {
        self.records.lock().map(|r| r.clone()).unwrap_or_default()
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
        let clock = Clock {
            run: self.created,
            stage: start,
            step: self.started.fetch_add(1, Ordering::Relaxed) + 1,
        };
        let mut bar = None;
        let mut ticker = None;
        match (self.mode, &self.multi) {
            (Mode::Bars, Some(m)) => {
                let b = match total {
                    Some(t) => indicatif::ProgressBar::new(t),
                    None => indicatif::ProgressBar::new_spinner(),
                };
                let style = indicatif::ProgressStyle::with_template(&format!(
                    "{{prefix:>8}} [{{bar:30}}] {{human_pos}}/{{human_len}} {unit} {{rate}} {{elapsed}} eta {{eta}}"
                ))
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .with_key(
                    "rate",
                    |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                        let _ = write!(w, "{}/s", indicatif::HumanCount(s.per_sec().round() as u64));
                    },
                )
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
                            clock,
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
            clock,
            bar,
            ticker,
            json: matches!(self.mode, Mode::Json { .. }),
            records: Some(Arc::clone(&self.records)),
            start_secs: self.created.elapsed().as_secs_f64(),
            multi: self.multi.clone(),
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
    clock: Clock,
    bar: Option<indicatif::ProgressBar>,
    ticker: Option<(Sender<()>, std::thread::JoinHandle<()>)>,
    json: bool,
    /// Where the finished stage is recorded (taken when it is).
    records: Option<Arc<Mutex<Vec<StageRecord>>>>,
    start_secs: f64,
    multi: Option<indicatif::MultiProgress>,
}

impl Stage {
    /// Count `n` more units done. Cheap; call per chunk, not per point.
    pub fn inc(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }

    /// A counter for work inside one large item (a cell's points): `tick` per unit is
    /// cheap, and the stage sees the units in batches of [`Ticker::BATCH`], so a running
    /// stage's lines move while a big cell is still being worked on.
    pub fn ticker(&self) -> Ticker<'_> {
        Ticker {
            stage: self,
            pending: 0,
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
                self.clock,
                extra,
            );
        }
    }

    fn stop(&mut self) {
        if let Some((tx, h)) = self.ticker.take() {
            drop(tx);
            let _ = h.join();
        }
        let secs = self.clock.stage.elapsed().as_secs_f64();
        // A finished bar gives way to one line: the stage, its count, time and rate, and the
        // run's time so far.
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
            let done = self.done();
            let line = format!(
                "{:>8}  {} {} in {:.1} s ({}/s), run {:.1} s",
                self.name,
                indicatif::HumanCount(done),
                self.unit,
                secs,
                indicatif::HumanCount(if secs > 0.0 {
                    (done as f64 / secs).round() as u64
                } else {
                    0
                }),
                self.clock.run.elapsed().as_secs_f64()
            );
            match &self.multi {
                Some(m) => {
                    let _ = m.println(line);
                }
                None => eprintln!("{line}"),
            }
        }
        if let Some(r) = self.records.take()
            && let Ok(mut r) = r.lock()
        {
            r.push(StageRecord {
                name: self.name.clone(),
                unit: self.unit.to_string(),
                done: self.done(),
                total: self.total,
                secs,
                start_secs: self.start_secs,
                peak_rss_bytes: crate::exec::peak_rss_bytes(),
            });
        }
    }
}

/// Counts units for a [`Stage`] in batches; what is pending is counted when it is dropped.
#[derive(Debug)]
pub struct Ticker<'a> {
    stage: &'a Stage,
    pending: u64,
}

impl Ticker<'_> {
    /// Units counted locally before they are added to the stage.
    pub const BATCH: u64 = 4096;

    /// One unit done.
    pub fn tick(&mut self) {
        self.pending += 1;
        if self.pending >= Self::BATCH {
            self.stage.inc(self.pending);
            self.pending = 0;
        }
    }
}

impl Drop for Ticker<'_> {
    fn drop(&mut self) {
        if self.pending > 0 {
            self.stage.inc(self.pending);
        }
    }
}

impl Drop for Stage {
    fn drop(&mut self) {
        self.stop();
    }
}

/// When a stage started, when its command did, and the stage's ordinal in the command.
#[derive(Debug, Clone, Copy)]
struct Clock {
    run: Instant,
    stage: Instant,
    step: u64,
}

/// One JSON progress line. `elapsed_s` is the stage's time, `run_s` the command's, `step`
/// the stage's ordinal among the command's stages; `eta_s` (running, with a known total and
/// some done) extrapolates the stage's rate.
fn emit(
    name: &str,
    state: &str,
    done: u64,
    total: Option<u64>,
    unit: &str,
    clock: Clock,
    extra: Option<serde_json::Value>,
) {
    let ms = |s: f64| (s * 1000.0).round() / 1000.0;
    let secs = clock.stage.elapsed().as_secs_f64();
    let mut v = serde_json::json!({
        "time": timestamp(SystemTime::now()),
        "stage": name,
        "step": clock.step,
        "state": state,
        "done": done,
        "total": total,
        "unit": unit,
        "elapsed_s": ms(secs),
        "run_s": ms(clock.run.elapsed().as_secs_f64()),
        "per_s": if secs > 0.0 { (done as f64 / secs).round() } else { 0.0 },
        "peak_rss_bytes": crate::exec::peak_rss_bytes(),
    });
    if let (Some(t), Some(o)) = (total, v.as_object_mut())
        && state == "running"
        && done > 0
        && done < t
    {
        o.insert(
            "eta_s".into(),
            serde_json::json!((secs * (t - done) as f64 / done as f64).round()),
        );
    }
    if let (Some(serde_json::Value::Object(m)), Some(o)) = (extra, v.as_object_mut()) {
        o.extend(m);
    }
    eprintln!("{v}");
}

/// `t` as an ISO 8601 UTC timestamp with milliseconds: `2026-11-26T21:58:03.123Z`.
pub fn timestamp(t: SystemTime) -> String {
    let d = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or(Duration::ZERO);
    let secs = d.as_secs() as i64;
    let (year, month, day) = civil_from_days(secs.div_euclid(86_400));
    let rem = secs.rem_euclid(86_400);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60,
        d.subsec_millis()
    )
}

/// The proleptic Gregorian date (year, month, day) `days` after 1970-01-01 (H. Hinnant's
/// `civil_from_days`).
pub fn civil_from_days(days: i64) -> (i64, i64, i64) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(month <= 2), month, day)
}

#[cfg(test)]
mod timestamp_tests {
    use super::*;

    #[test]
    fn timestamps_are_utc_calendar_dates() {
        let at = |s: u64, ms: u64| {
            timestamp(SystemTime::UNIX_EPOCH + Duration::from_millis(s * 1000 + ms))
        };
        assert_eq!(at(0, 0), "1970-01-01T00:00:00.000Z");
        assert_eq!(at(951_782_400, 5), "2000-02-29T00:00:00.005Z");
        assert_eq!(at(1_795_729_083, 123), "2026-11-26T21:38:03.123Z");
        assert_eq!(at(4_107_542_399, 999), "2100-02-28T23:59:59.999Z");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ticker_counts_in_batches_while_it_runs_and_the_rest_when_dropped() {
        let p = Progress::quiet();
        let stage = p.stage("normals", Some(10_000), "points");
        {
            let mut t = stage.ticker();
            for _ in 0..Ticker::BATCH - 1 {
                t.tick();
            }
            assert_eq!(stage.done(), 0);
            t.tick();
            // The stage sees the batch before the item is finished.
            assert_eq!(stage.done(), Ticker::BATCH);
            for _ in 0..10 {
                t.tick();
            }
            assert_eq!(stage.done(), Ticker::BATCH);
        }
        assert_eq!(stage.done(), Ticker::BATCH + 10);
        stage.finish(None);
    }

    #[test]
    fn stages_are_numbered_in_the_order_they_start() {
        let p = Progress::quiet();
        let a = p.stage("count", None, "points");
        let b = p.stage("scatter", None, "points");
        assert_eq!((a.clock.step, b.clock.step), (1, 2));
        assert!(b.clock.run <= b.clock.stage);
    }
}
