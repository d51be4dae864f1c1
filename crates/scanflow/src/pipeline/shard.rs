//! Shards: one slice of a reconstruction's work, run by one task of a cluster array job
//! (SLURM, Kubernetes Indexed Jobs, AWS Batch) against a work directory every task shares.
//!
//! **No scheduler, no barrier.** A run's work items are its leaves and its tiles, each in
//! Morton order. Shard `I` of `N` owns the `I`-th of `N` contiguous slices of each list
//! ([`Shard::slice`]); it visits its own slice first, then the other slices, each from its
//! far end ([`Shard::order`]), in two passes:
//!
//! 1. An item whose checkpoint exists is done and skipped. Any other is claimed before it is
//!    worked on: a claim is a file created exclusively ([`Claims`]), so that of the shards
//!    reaching an item one takes it and the others pass on. A shard that runs out of its own
//!    work so takes the items of a slower or not yet started shard, without repeating any.
//! 2. Then every item still without a checkpoint, claimed or not: a claim whose owner was
//!    killed (or requeued, or is still at it) never holds the run up.
//!
//! No shard ever waits for another, and a lost task costs time, not the run. Two shards
//! working on the same item in the second pass compute the same bytes and each renames its
//! own temporary file onto the same name: work repeats (at most what the others hold at
//! that moment), nothing is corrupted, and no finished item is done again. The tiles need
//! every leaf (the iso-value is the mean over all of them); a shard reaches them only after
//! every leaf checkpoint exists, which its second pass makes true.
//!
//! **What the file system must give.** `rename(2)` of a file within a directory is atomic,
//! which local file systems and NFS (one server operation) guarantee, so that a checkpoint is
//! whole or absent. An exclusive create (`O_CREAT | O_EXCL`) is atomic on local file systems
//! and on NFS from version 3 on, for the claims; `link(2)`, which fails when its target
//! exists, publishes the run description once ([`crate::pipeline::workdir`]). Temporary names
//! carry the host as well as the pid, so that tasks on two hosts never share one. Nothing
//! relies on advisory locks (often off on cluster mounts), on clocks agreeing between hosts
//! or on a claim's owner being alive: the second pass makes claims a hint, never a lock.
//!
//! **Stages.** Ingest is split the same way, into its own array of tasks
//! ([`crate::pipeline::ingest_split`]: count, scatter, assembly and normals items, the store
//! written by whichever task finds the last item done); the shards' reconstruction leaves
//! every tile's mesh checkpointed and the description `merge` reads; `merge` welds the tiles
//! in Morton order into the same bytes one process writes. The job script chains the three
//! with dependencies (`sbatch --dependency=afterok`); a run on one machine is the one shard
//! `0/1` whose tiles go straight to the welder instead of through their checkpoints.

use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::error::{Error, IoContext, Result, Setting};

/// One slice of a run: shard `index` of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, from 0.
    pub index: u32,
    /// How many shards share the run.
    pub count: u32,
    /// Whether the run is split (`--shard` given, even `0/1`: a re-submitted task of an array
    /// of one is still a shard of the run it joins).
    split: bool,
}

/// The most shards a run may be split into.
pub const MAX_SHARDS: u32 = 100_000;

impl Shard {
    /// The whole run in one process.
    pub const ALL: Shard = Shard {
        index: 0,
        count: 1,
        split: false,
    };

    /// Shard `index` of `count` of a split run (`index < count`, unchecked: see
    /// [`Shard::parse`] for the checked form).
    pub fn new(index: u32, count: u32) -> Shard {
        Shard {
            index,
            count,
            split: true,
        }
    }

    /// Whether the run is split over several tasks sharing the work directory (`--shard`
    /// given, even `0/1`): checkpoints of other tasks are then reused without `--resume`, and
    /// the tiles are left for `merge`.
    pub fn is_split(&self) -> bool {
        self.split
    }

    /// The shard `--shard` names: `I/N` (0 ≤ I < N), `auto` (from SLURM's array variables) or
    /// `auto/N` (the index from `SLURM_ARRAY_TASK_ID`, `JOB_COMPLETION_INDEX` or
    /// `AWS_BATCH_JOB_ARRAY_INDEX`, the count given: Kubernetes and AWS Batch do not put it
    /// in the environment). `env` reads a variable.
    pub fn parse(text: &str, env: impl Fn(&str) -> Option<String>) -> Result<Shard> {
        let bad = |why: String| Error::Usage(format!("{} {text}: {why}", Setting::Shard));
        let num = |name: &str, v: &str| -> Result<u32> {
            v.trim()
                .parse::<u32>()
                .map_err(|_| bad(format!("{name} is {v:?}, not a whole number")))
        };
        // SLURM numbers the tasks from SLURM_ARRAY_TASK_MIN (`--array=1-3`): the shard is the
        // task's offset from it.
        let slurm_index = |id: &str| -> Result<u32> {
            let min = env("SLURM_ARRAY_TASK_MIN").unwrap_or_else(|| "0".into());
            let (id, min) = (
                num("SLURM_ARRAY_TASK_ID", id)?,
                num("SLURM_ARRAY_TASK_MIN", &min)?,
            );
            id.checked_sub(min).ok_or_else(|| {
                bad(format!(
                    "SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
                ))
            })
        };
        let (index, count) = match text.split_once('/') {
            None if text == "auto" => {
                let id = env("SLURM_ARRAY_TASK_ID").ok_or_else(|| {
                    bad("SLURM_ARRAY_TASK_ID is not set: `auto` alone reads SLURM's array job variables; give the count as auto/N under Kubernetes (JOB_COMPLETION_INDEX) or AWS Batch (AWS_BATCH_JOB_ARRAY_INDEX), or I/N by hand".into())
                })?;
                let count = env("SLURM_ARRAY_TASK_COUNT")
                    .ok_or_else(|| bad("SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not (SLURM 18.08 or later sets both)".into()))?;
                (slurm_index(&id)?, num("SLURM_ARRAY_TASK_COUNT", &count)?)
            }
            None => {
                return Err(bad(
                    "expected I/N (shard I of N, from 0), auto or auto/N".into()
                ));
            }
            Some(("auto", n)) => {
                let count = num("the count", n)?;
                let vars = [
                    "SLURM_ARRAY_TASK_ID",
                    "JOB_COMPLETION_INDEX",
                    "AWS_BATCH_JOB_ARRAY_INDEX",
                ];
                let (name, v) = vars
                    .iter()
                    .find_map(|&v| env(v).map(|x| (v, x)))
                    .ok_or_else(|| {
                        bad(format!(
                            "none of {} is set: is this a task of an array job?",
                            vars.join(", ")
                        ))
                    })?;
                let id = if name == "SLURM_ARRAY_TASK_ID" {
                    slurm_index(&v)?
                } else {
                    num(name, &v)?
                };
                (id, count)
            }
            Some((i, n)) => (num("the index", i)?, num("the count", n)?),
        };
        if count == 0 || count > MAX_SHARDS {
            return Err(bad(format!("{count} shards: expected 1 to {MAX_SHARDS}")));
        }
        if index >= count {
            return Err(bad(format!(
                "shard {index} of {count}: shards are numbered from 0 to {}",
                count - 1
            )));
        }
        Ok(Shard::new(index, count))
    }

    /// The slice of `n` items shard `index` owns: the `index`-th of `count` contiguous,
    /// near-equal slices.
    pub fn slice(&self, n: usize) -> Range<usize> {
        self.slice_of(self.index, n)
    }

    fn slice_of(&self, index: u32, n: usize) -> Range<usize> {
        let at = |i: u32| (n as u128 * i as u128 / self.count as u128) as usize;
        at(index)..at(index + 1)
    }

    /// The passes over the work items, each saying whether it claims them: a split run
    /// claims in its first pass and then does every item still missing (see the [module
    /// docs](self)); the whole run in one process makes one pass without claims.
    pub fn passes(&self) -> &'static [bool] {
        if self.split { &[true, false] } else { &[false] }
    }

    /// The order this shard visits `n` items in: its own slice forwards, then each following
    /// shard's slice (wrapping round) from its far end, where its owner reaches last.
    pub fn order(&self, n: usize) -> Vec<usize> {
        let mut v: Vec<usize> = self.slice(n).collect();
        for k in 1..self.count {
            let other = (self.index + k) % self.count;
            v.extend(self.slice_of(other, n).rev());
        }
        v
    }
}

/// The claims of a split run's shards on work items: one file per item, created exclusively
/// (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct Claims {
    dir: PathBuf,
}

impl Claims {
    /// The claims in the directory `dir` (made by the work directory's preparation).
    pub fn new(dir: &Path) -> Claims {
        Claims {
            dir: dir.to_path_buf(),
        }
    }

    /// Claim the item `name` for this process: whether this call made the claim (false: some
    /// shard claimed it first). The claim records the host and pid, for people reading it.
    pub fn take(&self, name: &str) -> Result<bool> {
        let path = self.dir.join(name);
        match std::fs::File::create_new(&path) {
            Ok(mut f) => {
                let host = crate::fs::atomic::this_host();
                writeln!(f, "{host} {}", std::process::id()).with_path(&path)?;
                Ok(true)
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(false),
            Err(e) => Err(Error::io(&path, e)),
        }
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn every_item_is_owned_once_and_every_shard_visits_all() {
        for n in [0, 1, 2, 7, 100] {
            for count in [1, 2, 3, 5, 8] {
                let mut owned = vec![0; n];
                for index in 0..count {
                    let s = Shard::new(index, count);
                    for i in s.slice(n) {
                        owned[i] += 1;
                    }
                    let mut o = s.order(n);
                    assert_eq!(&o[..s.slice(n).len()], &s.slice(n).collect::<Vec<_>>()[..]);
                    o.sort();
                    assert_eq!(o, (0..n).collect::<Vec<_>>(), "shard {s} of {n}");
                }
                assert!(owned.iter().all(|&c| c == 1), "{n} items, {count} shards");
            }
        }
        // The others' slices from their far ends.
        assert_eq!(Shard::new(0, 3).order(6), [0, 1, 3, 2, 5, 4]);
        assert!(Shard::new(0, 1).is_split() && !Shard::ALL.is_split());
    }

    #[test]
    fn an_item_is_claimed_once() {
        let d = tempfile::tempdir().unwrap();
        let (a, b) = (Claims::new(d.path()), Claims::new(d.path()));
        assert!(a.take("L1").unwrap());
        assert!(!b.take("L1").unwrap() && !a.take("L1").unwrap());
        assert!(b.take("T1").unwrap());
        let e = Claims::new(&d.path().join("none")).take("L1").unwrap_err();
        assert!(e.to_string().contains("none"), "{e}");
    }

    #[test]
    fn shards_come_from_the_text_or_the_array_job() {
        let none = env(&[]);
        assert_eq!(Shard::parse("2/5", &none).unwrap(), Shard::new(2, 5));
        for bad in ["5/5", "1/0", "x/2", "3", "auto", "auto/2", "-1/3"] {
            let e = Shard::parse(bad, &none).unwrap_err().to_string();
            assert!(e.contains(&format!("`shard` {bad}")), "{e}");
        }
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "2"),
        ]);
        assert_eq!(Shard::parse("auto", &slurm).unwrap(), Shard::new(2, 3));
        let k8s = env(&[("JOB_COMPLETION_INDEX", "1")]);
        assert_eq!(Shard::parse("auto/4", &k8s).unwrap(), Shard::new(1, 4));
        assert!(Shard::parse("auto/1", &k8s).is_err());
    }
}
