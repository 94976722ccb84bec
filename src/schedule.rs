//! Running jobs on worker threads, each with its own database clone: a panic fails only its
//! job, a raised cancel flag unwinds the workers' queries (salsa cancellation), and each clone
//! is dropped as soon as its worker finishes, so that the writer never waits long. Jobs come in
//! waves: a job may schedule more, for a later wave (render groups once the layout is known,
//! surfaces once the renders are done).

use std::collections::BTreeMap;
use std::panic::AssertUnwindSafe;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use crate::db::Database;
use crate::diagnostic::Diagnostic;
use crate::kinds::Job;

/// A flag that cancels a running build when raised.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Arc<std::sync::atomic::AtomicBool>);

impl CancelFlag {
    pub fn raise(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    pub fn lower(&self) {
        self.0.store(false, Ordering::SeqCst);
    }

    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// The cores this process works on (the worker threads of its thread pool): one job worker each.
pub fn cores() -> usize {
    rayon::current_num_threads()
}

/// Progress of the stage work of a build, for progress bars and logs.
#[derive(Clone, Debug)]
pub struct Progress {
    pub done: usize,
    pub total: usize,
    /// What just finished, e.g. `bark/oak_bark/albedo`.
    pub item: String,
}

/// Runs every job and the jobs they schedule, wave by wave; each finished job with its result.
/// `None` when the build was cancelled.
pub fn run_jobs(
    db: &Database,
    first: Vec<Job>,
    progress: &(dyn Fn(Progress) + Sync),
    cancel: &CancelFlag,
) -> Option<Vec<(Job, Result<(), Diagnostic>)>> {
    let mut waves: BTreeMap<u32, Vec<Job>> = BTreeMap::from([(0, first)]);
    let mut finished = Vec::new();
    let mut total = waves[&0].len();
    while let Some((wave, jobs)) = waves.pop_first() {
        let done_before = finished.len();
        let report = |Progress { done, item, .. }: Progress| progress(Progress { done: done_before + done, total, item });
        let results = run_parallel(
            db,
            &jobs,
            &|db, job: &Job| (job.asset.main_file(db).clone(), job.label.clone()),
            &|db, job: &Job| crate::cache::with_asset(job.asset.name(db), || job.asset.kind(db).run_job(db, job)),
            &report,
            cancel,
        );
        for (job, result) in jobs.into_iter().zip(results) {
            let result = result?;
            match result {
                Ok(follow_ups) => {
                    total += follow_ups.len();
                    for follow_up in follow_ups {
                        waves.entry(wave + follow_up.after.max(1)).or_default().push(follow_up);
                    }
                    finished.push((job, Ok(())));
                }
                Err(diagnostic) => finished.push((job, Err(diagnostic))),
            }
        }
    }
    Some(finished)
}

/// Runs `work` for every item on worker threads, each with its own database clone; a panic
/// fails only its item. `describe` names an item's file (for that failure) and progress label.
/// Raising `cancel` stops the workers: those inside a query unwind with `salsa::Cancelled`
/// (their clones' cancellation tokens), the rest take no new item; unfinished items are `None`.
pub fn run_parallel<T: Sync, R: Send>(
    db: &Database,
    items: &[T],
    describe: &(dyn Fn(&Database, &T) -> (PathBuf, String) + Sync),
    work: &(dyn Fn(&Database, &T) -> Result<R, Diagnostic> + Sync),
    progress: &(dyn Fn(Progress) + Sync),
    cancel: &CancelFlag,
) -> Vec<Option<Result<R, Diagnostic>>> {
    let results: Mutex<Vec<Option<Result<R, Diagnostic>>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let running = AtomicUsize::new(0);
    let workers = cores().min(items.len().max(1));
    let clones: Vec<Database> = (0..workers).map(|_| db.clone()).collect();
    let tokens: Vec<salsa::CancellationToken> = clones.iter().map(salsa::Database::cancellation_token).collect();
    std::thread::scope(|scope| {
        for db in clones {
            let (results, next, done, running) = (&results, &next, &done, &running);
            running.fetch_add(1, Ordering::SeqCst);
            scope.spawn(move || {
                loop {
                    if cancel.is_raised() {
                        break;
                    }
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    let Some(item) = items.get(index) else { break };
                    let result = match std::panic::catch_unwind(AssertUnwindSafe(|| work(&db, item))) {
                        Ok(result) => result,
                        Err(panic) if panic.is::<salsa::Cancelled>() => break,
                        Err(panic) => {
                            let message = panic
                                .downcast_ref::<String>()
                                .cloned()
                                .or_else(|| panic.downcast_ref::<&str>().map(|text| text.to_string()))
                                .unwrap_or_else(|| "unknown panic".to_string());
                            let (file, label) = describe(&db, item);
                            Err(Diagnostic::new(file, format!("internal error while baking `{label}`: {message}")))
                        }
                    };
                    results.lock().expect("results lock")[index] = Some(result);
                    let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
                    progress(Progress { done: finished, total: items.len(), item: describe(&db, item).1 });
                }
                // The clone is dropped here, before the writer can set the next inputs.
                drop(db);
                running.fetch_sub(1, Ordering::SeqCst);
            });
        }
        // Watch for cancellation while the workers run; pass it on to their queries.
        while running.load(Ordering::SeqCst) > 0 {
            if cancel.is_raised() {
                tokens.iter().for_each(salsa::CancellationToken::cancel);
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    });
    results.into_inner().expect("results lock")
}

/// A memory budget shared by threads: work reserves its working set before it runs and gives
/// it back when done, waiting while others hold so much that both would not fit. Work alone
/// always proceeds (a single working set larger than the budget is refused earlier, from the
/// texture's header).
pub struct MemoryBudget {
    reserved: Mutex<u64>,
    released: std::sync::Condvar,
}

/// The process's texture memory budget: every texture's mips and encode reserve from it, so
/// that the budget bounds the whole process, not each texture (more cores run more jobs, not
/// more of them at once than the memory allows).
pub static TEXTURE_MEMORY: MemoryBudget = MemoryBudget::new();

/// Memory reserved from a [`MemoryBudget`], given back when dropped.
pub struct MemoryReservation<'a> {
    budget: &'a MemoryBudget,
    bytes: u64,
}

impl MemoryBudget {
    pub const fn new() -> MemoryBudget {
        MemoryBudget { reserved: Mutex::new(0), released: std::sync::Condvar::new() }
    }

    /// Reserves `bytes` of `limit`, waiting while others hold so much that both would not fit.
    /// Hold it over pure work only (no query inside), so that no job waits on another's query.
    pub fn reserve(&self, bytes: u64, limit: u64) -> MemoryReservation<'_> {
        let mut in_use = self.reserved.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        while *in_use > 0 && in_use.saturating_add(bytes) > limit {
            in_use = self.released.wait(in_use).unwrap_or_else(|poisoned| poisoned.into_inner());
        }
        *in_use += bytes;
        MemoryReservation { budget: self, bytes }
    }

    /// The bytes reserved now.
    pub fn reserved(&self) -> u64 {
        *self.reserved.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl Default for MemoryBudget {
    fn default() -> Self {
        MemoryBudget::new()
    }
}

impl Drop for MemoryReservation<'_> {
    fn drop(&mut self) {
        *self.budget.reserved.lock().unwrap_or_else(|poisoned| poisoned.into_inner()) -= self.bytes;
        self.budget.released.notify_all();
    }
}
