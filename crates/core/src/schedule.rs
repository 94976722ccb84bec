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

use crate::db::{Asset, Database, Db};
use crate::diagnostic::Diagnostic;

/// Work for a worker thread: one task of an asset (what a task is, the kinds say).
#[derive(Clone, Debug, PartialEq)]
pub struct Job<T> {
    pub asset: Asset,
    pub task: T,
    /// Waves to wait after the wave that scheduled it (jobs of one wave run in parallel).
    pub after: u32,
    /// For progress and for naming the job in an internal error.
    pub label: String,
}

/// What the scheduler asks of a job's task.
pub trait JobTask: Clone + Send + Sync {
    /// The sort of work it is, for estimating how long the waiting ones take (jobs of one sort
    /// take about as long as each other).
    fn sort(&self) -> &'static str;
}

/// Each finished job with its result (its follow-ups are scheduled, not returned).
pub type FinishedJobs<T> = Vec<(Job<T>, Result<(), Diagnostic>)>;

/// Runs one job, returning the jobs it schedules.
pub type RunJob<'a, T> = &'a (dyn Fn(&dyn Db, &Job<T>) -> Result<Vec<Job<T>>, Diagnostic> + Sync);

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
    /// Its index among the items of its run.
    pub index: usize,
    /// Seconds of work the jobs known so far still need on the workers, estimated from the jobs
    /// of each sort finished so far (see [`remaining_seconds`]); `None` before any finished.
    pub remaining_seconds: Option<f64>,
    /// Seconds the finished jobs took, summed over the workers (in a run's own report: the
    /// item's alone).
    pub worked_seconds: f64,
}

impl Progress {
    /// How far the build is, weighted by each job's cost (finished: what it took; waiting: the
    /// estimate), in [0, 1]; by job count before any estimate.
    pub fn fraction(&self) -> f64 {
        match self.remaining_seconds {
            Some(remaining) if self.worked_seconds + remaining > 0.0 => {
                self.worked_seconds / (self.worked_seconds + remaining)
            }
            _ => self.done as f64 / self.total.max(1) as f64,
        }
    }
}

/// The seconds the `waiting` jobs (a count per sort: a kind's step, a texture surface) will take
/// on `workers` workers, each sort at the mean of its `finished` jobs (seconds summed, count),
/// a sort not seen yet at the mean of all: so that a bar over a few long AO tiles and hundreds
/// of quick surfaces moves with the time, not the count. `None` before any job finished.
pub fn remaining_seconds(
    finished: &BTreeMap<&str, (f64, usize)>,
    waiting: &BTreeMap<&str, usize>,
    workers: usize,
) -> Option<f64> {
    let (sum, count) = finished.values().fold((0.0, 0), |(sum, count), (seconds, jobs)| (sum + seconds, count + jobs));
    if count == 0 {
        return None;
    }
    let overall = sum / count as f64;
    let mean = |sort: &str| {
        finished.get(sort).filter(|(_, jobs)| *jobs > 0).map_or(overall, |(seconds, jobs)| seconds / *jobs as f64)
    };
    let total: f64 = waiting.iter().map(|(sort, jobs)| mean(sort) * *jobs as f64).sum();
    Some(total / workers.max(1) as f64)
}

/// Runs every job and the jobs they schedule, wave by wave; each finished job with its result.
/// `None` when the build was cancelled.
pub fn run_jobs<T: JobTask>(
    db: &Database,
    first: Vec<Job<T>>,
    run: RunJob<'_, T>,
    progress: &(dyn Fn(Progress) + Sync),
    cancel: &CancelFlag,
) -> Option<FinishedJobs<T>> {
    let mut waves: BTreeMap<u32, Vec<Job<T>>> = BTreeMap::from([(0, first)]);
    let mut finished = Vec::new();
    let mut total = waves[&0].len();
    // Seconds and count of the finished jobs per sort, and the jobs known but not finished.
    let finished_by_sort: Mutex<BTreeMap<&'static str, (f64, usize)>> = Mutex::new(BTreeMap::new());
    let mut waiting_by_sort: BTreeMap<&'static str, usize> = BTreeMap::new();
    for job in &waves[&0] {
        *waiting_by_sort.entry(job.task.sort()).or_default() += 1;
    }
    let waiting_by_sort = Mutex::new(waiting_by_sort);
    let worked = Mutex::new(0.0f64);
    while let Some((wave, jobs)) = waves.pop_first() {
        let done_before = finished.len();
        let report = |Progress { done, item, index, worked_seconds: seconds, .. }: Progress| {
            let sort = jobs[index].task.sort();
            let mut by_sort = finished_by_sort.lock().expect("progress lock");
            let entry = by_sort.entry(sort).or_default();
            *entry = (entry.0 + seconds, entry.1 + 1);
            let mut waiting = waiting_by_sort.lock().expect("progress lock");
            if let Some(count) = waiting.get_mut(sort) {
                *count = count.saturating_sub(1);
            }
            let remaining_seconds = remaining_seconds(&by_sort, &waiting, cores());
            let mut worked = worked.lock().expect("progress lock");
            *worked += seconds;
            progress(Progress {
                done: done_before + done,
                total,
                item,
                index,
                remaining_seconds,
                worked_seconds: *worked,
            })
        };
        let results = run_parallel(
            db,
            &jobs,
            &|db, job: &Job<T>| (job.asset.main_file(db).clone(), job.label.clone()),
            &|db, job: &Job<T>| crate::cache::with_asset(job.asset.name(db), || run(db, job)),
            &report,
            cancel,
        );
        for (job, result) in jobs.into_iter().zip(results) {
            let result = result?;
            match result {
                Ok(follow_ups) => {
                    total += follow_ups.len();
                    for follow_up in follow_ups {
                        *waiting_by_sort.lock().expect("progress lock").entry(follow_up.task.sort()).or_default() += 1;
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

/// What an item reports when a query it waited for panicked on another thread (whose own item
/// reports the panic's message).
pub const PROPAGATED_PANIC: &str = "a stage it waited for panicked on another worker (see the error reported there)";

/// Runs `work` for every item on worker threads, each with its own database clone; a panic
/// fails only its item, and so does a query's panic on another thread that this item's query
/// waited for (salsa unwinds the waiter with `Cancelled::PropagatedPanic`): that is not a
/// cancellation. `describe` names an item's file (for that failure) and progress label. Raising
/// `cancel` stops the workers: those inside a query unwind with `salsa::Cancelled` (their
/// clones' cancellation tokens), the rest take no new item; unfinished items are `None`.
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
                    let started = std::time::Instant::now();
                    let result = match std::panic::catch_unwind(AssertUnwindSafe(|| work(&db, item))) {
                        Ok(result) => result,
                        Err(panic) => {
                            let cancelled = panic.downcast_ref::<salsa::Cancelled>();
                            let propagated = matches!(cancelled, Some(salsa::Cancelled::PropagatedPanic));
                            if cancelled.is_some() && (!propagated || cancel.is_raised()) {
                                break;
                            }
                            let message = panic
                                .downcast_ref::<String>()
                                .cloned()
                                .or_else(|| panic.downcast_ref::<&str>().map(|text| text.to_string()))
                                .unwrap_or_else(|| {
                                    let unknown = if propagated { PROPAGATED_PANIC } else { "unknown panic" };
                                    unknown.to_string()
                                });
                            let (file, label) = describe(&db, item);
                            Err(Diagnostic::new(file, format!("internal error while baking `{label}`: {message}")))
                        }
                    };
                    results.lock().expect("results lock")[index] = Some(result);
                    let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
                    let worked_seconds = started.elapsed().as_secs_f64();
                    progress(Progress {
                        done: finished,
                        total: items.len(),
                        item: describe(&db, item).1,
                        index,
                        remaining_seconds: None,
                        worked_seconds,
                    });
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
    /// The most any reservation's `limit` may allow (the process's memory budget's share for
    /// work in flight, set by the driver; `u64::MAX` until then).
    ceiling: std::sync::atomic::AtomicU64,
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
        MemoryBudget {
            reserved: Mutex::new(0),
            released: std::sync::Condvar::new(),
            ceiling: std::sync::atomic::AtomicU64::new(u64::MAX),
        }
    }

    /// Bounds every later reservation's limit to `bytes` (the process's memory budget's share
    /// for work in flight), whatever limit the caller names: a texture limit of 4 GiB does not
    /// let the jobs of many cores pass a 1 GiB process budget. Only how many jobs run at once
    /// depends on it, never what they make; work alone still always proceeds.
    pub fn set_ceiling(&self, bytes: u64) {
        self.ceiling.store(bytes, std::sync::atomic::Ordering::Relaxed);
        self.released.notify_all();
    }

    /// Reserves `bytes` of `limit` (or of the ceiling, where lower), waiting while others hold
    /// so much that both would not fit. Hold it over pure work only (no query inside), so that
    /// no job waits on another's query.
    pub fn reserve(&self, bytes: u64, limit: u64) -> MemoryReservation<'_> {
        let limit = limit.min(self.ceiling.load(std::sync::atomic::Ordering::Relaxed));
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
