//! Execution: the memory budget, the worker pool, ordering, and progress.
//!
//! Every large allocation is admitted by one [`budget::Budget`] before it is made; a task that
//! does not fit waits on a condition variable. Work runs on a rayon pool of exactly
//! `--threads` workers; output order is fixed by sequence numbers, never by thread timing.

pub mod alloc;
pub mod budget;
pub mod cache;
pub mod progress;

use crate::error::{Error, Result, Setting};

/// Build the worker pool: exactly `threads` workers (0 means one per available core).
pub fn pool(threads: usize) -> Result<rayon::ThreadPool> {
    let n = if threads == 0 {
        default_threads()
    } else {
        threads
    };
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .thread_name(|i| format!("scanflow-worker-{i}"))
        .build()
        .map_err(|e| Error::Internal(format!("cannot start {n} worker threads: {e}")))
}

/// One worker per available core.
pub fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// Peak resident set size of this process so far, in bytes (Linux `VmHWM`; 0 elsewhere).
pub fn peak_rss_bytes() -> u64 {
    proc_status_kib("VmHWM:") * 1024
}

/// Current resident set size in bytes (Linux `VmRSS`; 0 elsewhere).
pub fn rss_bytes() -> u64 {
    proc_status_kib("VmRSS:") * 1024
}

/// The resident memory of this process over time, sampled by a thread from its start to
/// [`MemoryTimeline::stop`]: for the run report's memory plot.
///
/// Samples start every [`MemoryTimeline::FIRST_EVERY`]; when [`MemoryTimeline::MOST`] are
/// held, every other one is dropped and the interval doubles, so a night-long run keeps as
/// few as a short one, evenly spread.
pub struct MemoryTimeline {
    stop: crossbeam_channel::Sender<()>,
    thread: std::thread::JoinHandle<Vec<(f64, u64)>>,
}

impl MemoryTimeline {
    /// The first interval between samples.
    pub const FIRST_EVERY: std::time::Duration = std::time::Duration::from_millis(100);
    /// The most samples held.
    pub const MOST: usize = 1024;

    /// Start sampling.
    pub fn start() -> MemoryTimeline {
        let (stop, rx) = crossbeam_channel::bounded::<()>(0);
        let thread = std::thread::spawn(move || {
            let t0 = std::time::Instant::now();
            let mut every = Self::FIRST_EVERY;
            let mut samples = vec![(0.0, rss_bytes())];
            while let Err(crossbeam_channel::RecvTimeoutError::Timeout) = rx.recv_timeout(every) {
                samples.push((t0.elapsed().as_secs_f64(), rss_bytes()));
                if samples.len() >= Self::MOST {
                    let mut k = 0;
                    samples.retain(|_| {
                        k += 1;
                        k % 2 == 1
                    });
                    every *= 2;
                }
            }
            samples.push((t0.elapsed().as_secs_f64(), rss_bytes()));
            samples
        });
        MemoryTimeline { stop, thread }
    }

    /// Stop and return the samples: (seconds since the start, resident bytes).
    pub fn stop(self) -> Vec<(f64, u64)> {
        drop(self.stop);
        self.thread.join().unwrap_or_default()
    }
}

fn proc_status_kib(key: &str) -> u64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/status") else {
        return 0;
    };
    s.lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_ascii_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// Parse a memory size: `512M`, `4G`, `1.5GiB`, `1048576`, or a share of the machine's
/// available memory such as `50%`.
pub fn parse_mem(s: &str) -> Result<u64> {
    let t = s.trim();
    let bad = || {
        Error::Usage(format!(
            "{} \"{s}\": expected a size such as 512M, 4G, 1.5GiB, a byte count, or a percentage such as 50%",
            Setting::Mem
        ))
    };
    if let Some(p) = t.strip_suffix('%') {
        let v: f64 = p.trim().parse().map_err(|_| bad())?;
        if !(v > 0.0 && v <= 100.0) {
            return Err(Error::Usage(format!(
                "{} \"{s}\": a percentage must be in (0, 100]",
                Setting::Mem
            )));
        }
        return Ok((available_memory_bytes() as f64 * v / 100.0) as u64);
    }
    let upper = t.to_ascii_uppercase();
    let digits_end = upper
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(upper.len());
    let (num, unit) = upper.split_at(digits_end);
    let v: f64 = num.parse().map_err(|_| bad())?;
    let mult: u64 = match unit.trim() {
        "" | "B" => 1,
        "K" | "KB" | "KIB" => 1 << 10,
        "M" | "MB" | "MIB" => 1 << 20,
        "G" | "GB" | "GIB" => 1 << 30,
        "T" | "TB" | "TIB" => 1 << 40,
        _ => return Err(bad()),
    };
    let bytes = v * mult as f64;
    if bytes.is_nan() || bytes < 1.0 || !bytes.is_finite() {
        return Err(bad());
    }
    Ok(bytes as u64)
}

/// Memory the OS reports as available (sysinfo), in bytes.
pub fn available_memory_bytes() -> u64 {
    let mut sys = sysinfo::System::new();
    sys.refresh_memory();
    sys.available_memory()
}

/// The default `--mem`: half of the available memory.
pub fn default_mem_bytes() -> u64 {
    available_memory_bytes() / 2
}

/// Format a byte count for humans (`1.50 GiB`).
pub fn human_bytes(b: u64) -> String {
    const U: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut i = 0;
    while v >= 1024.0 && i + 1 < U.len() {
        v /= 1024.0;
        i += 1;
    }
    if i == 0 {
        format!("{b} B")
    } else {
        format!("{v:.2} {}", U[i])
    }
}

/// What every driver gets: the worker pool, the memory budget and the progress reporter.
pub struct Ctx {
    /// Exactly `--threads` workers.
    pub pool: rayon::ThreadPool,
    /// The one memory budget.
    pub budget: std::sync::Arc<budget::Budget>,
    /// Progress reporting.
    pub progress: progress::Progress,
}

impl Ctx {
    /// A context with `threads` workers (0: one per core) and `mem_bytes` of budget.
    /// The budget is `mem_bytes` less what [`alloc::for_run`] sets aside for the allocator.
    pub fn new(threads: usize, mem_bytes: u64, progress: progress::Progress) -> Result<Ctx> {
        let pool = pool(threads)?;
        let buffers = alloc::for_run(pool.current_num_threads(), mem_bytes);
        Ok(Ctx {
            pool,
            budget: budget::Budget::new(buffers),
            progress,
        })
    }

    /// Number of workers.
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mem_sizes() {
        assert_eq!(parse_mem("512M").unwrap(), 512 << 20);
        assert_eq!(parse_mem("4G").unwrap(), 4 << 30);
        assert_eq!(parse_mem("1.5GiB").unwrap(), 3 << 29);
        assert_eq!(parse_mem("1000").unwrap(), 1000);
        assert!(parse_mem("50%").unwrap() > 0);
        for bad in ["", "abc", "12Q", "0", "-5M", "150%", "0%"] {
            assert!(parse_mem(bad).is_err(), "{bad}");
        }
    }
}
