//! Runs file-writing jobs in parallel (rayon) while the calling thread
//! reports progress. Each job writes its own files from its own seed, so the
//! output does not depend on scheduling.

use std::ops::Add;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::Duration;

use rayon::prelude::*;

use crate::text::LiveCounters;
use crate::{GenError, GenProgress};

/// Counts a job contributes to the summary.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Tally {
    pub(crate) files: u64,
    pub(crate) bytes: u64,
    pub(crate) object_instances: u64,
    pub(crate) flattened_instances: u64,
    pub(crate) unique_triangles: u64,
    pub(crate) instanced_triangles: u64,
}

impl Tally {
    /// One file of `bytes`.
    pub(crate) fn file(bytes: u64) -> Tally {
        Tally {
            files: 1,
            bytes,
            ..Tally::default()
        }
    }
}

impl Add for Tally {
    type Output = Tally;

    fn add(self, o: Tally) -> Tally {
        Tally {
            files: self.files + o.files,
            bytes: self.bytes + o.bytes,
            object_instances: self.object_instances + o.object_instances,
            flattened_instances: self.flattened_instances + o.flattened_instances,
            unique_triangles: self.unique_triangles + o.unique_triangles,
            instanced_triangles: self.instanced_triangles + o.instanced_triangles,
        }
    }
}

/// What every job sees: the output root and the live counters.
pub(crate) struct Ctx<'a> {
    pub(crate) root: &'a Path,
    pub(crate) live: &'a LiveCounters,
}

pub(crate) type Job<'a> = Box<dyn Fn(&Ctx<'_>) -> Result<Tally, GenError> + Send + Sync + 'a>;

/// Runs `jobs` on `threads` threads (rayon's global pool when `None`).
pub(crate) fn run_jobs(
    root: &Path,
    jobs: Vec<Job<'_>>,
    threads: Option<usize>,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<Tally, GenError> {
    let live = LiveCounters::default();
    let files_total = jobs.len() as u64;
    let report = |live: &LiveCounters| GenProgress {
        files_written: live.files.load(Ordering::Relaxed),
        files_total: files_total.max(live.files.load(Ordering::Relaxed)),
        bytes_written: live.bytes.load(Ordering::Relaxed),
    };
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|scope| {
        let live_ref = &live;
        let jobs_ref = &jobs;
        scope.spawn(move || {
            let ctx = Ctx {
                root,
                live: live_ref,
            };
            let work = || {
                jobs_ref
                    .par_iter()
                    .map(|job| job(&ctx))
                    .try_reduce(Tally::default, |a, b| Ok(a + b))
            };
            let result = match threads {
                Some(n) => rayon::ThreadPoolBuilder::new()
                    .num_threads(n.max(1))
                    .build()
                    .map_err(GenError::ThreadPool)
                    .and_then(|pool| pool.install(work)),
                None => work(),
            };
            // The receiver lives until this thread is joined.
            let _ = tx.send(result);
        });
        loop {
            match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(result) => {
                    progress(report(&live));
                    return result;
                }
                Err(mpsc::RecvTimeoutError::Timeout) => progress(report(&live)),
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(GenError::Worker(
                        "the writer thread stopped without a result".into(),
                    ));
                }
            }
        }
    })
}
