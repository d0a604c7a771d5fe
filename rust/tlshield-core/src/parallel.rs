//! The thread pool of the batch calls, one per process.
//!
//! Rayon's global pool does not survive `fork`: the child inherits the pool's bookkeeping but
//! not its threads, so its first parallel call waits for workers that do not exist, forever
//! (Gymnasium's `AsyncVectorEnv` and `multiprocessing` fork by default on Linux). The batch
//! calls therefore run on a pool tagged with the id of the process that built it; a forked
//! child sees a different id and builds a fresh pool on its first batch call.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use smallvec::SmallVec;

use rayon::{ThreadPool, ThreadPoolBuilder};

/// Batches under this many rows run on the calling thread: waking the pool costs more than a few
/// microsecond-sized rows.
pub const MIN_ROWS: usize = 32;

/// The pool and the id of the process whose threads it owns.
static POOL: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

/// This process's pool, built on first use (again after a fork); `None` if threads cannot be
/// started, in which case the caller runs serially.
fn pool() -> Option<Arc<ThreadPool>> {
    let pid = std::process::id();
    let mut slot = POOL.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((owner, pool)) = slot.as_ref() {
        if *owner == pid {
            return Some(pool.clone());
        }
    }
    // A pool inherited through fork: its worker threads do not exist here, so dropping it
    // would wait on them. Leak it (one allocation per fork) and build this process's own.
    if let Some(inherited) = slot.take() {
        std::mem::forget(inherited);
    }
    let pool = Arc::new(ThreadPoolBuilder::new().build().ok()?);
    *slot = Some((pid, pool.clone()));
    Some(pool)
}

/// Runs `op` inside this process's pool, so that rayon's parallel iterators in it use
/// threads that exist (see the module docs); serially if no pool can be had.
pub fn install<R: Send>(op: impl FnOnce() -> R + Send) -> R {
    match pool() {
        Some(pool) => pool.install(op),
        None => op(),
    }
}

/// Runs `op` with a scope of this process's pool in which the calling thread works too: tasks
/// spawned on the scope run on the pool's threads while `op` goes on with its own share on the
/// caller's (nothing is handed off and waited for, which costs a thread wake-up when the
/// caller has been doing other work, as a PyTorch layer's caller has). `None`: no pool, serial.
pub fn in_place_scope<'scope, R>(op: impl FnOnce(Option<&rayon::Scope<'scope>>) -> R) -> R {
    match pool() {
        Some(pool) => pool.in_place_scope(|scope| op(Some(scope))),
        None => op(None),
    }
}

/// Threads of this process's pool (1 without one).
pub fn threads() -> usize {
    pool().map_or(1, |pool| pool.current_num_threads())
}

/// How many parts [`for_each_part`] callers cut a batch into per thread: enough that a thread
/// that wakes late finds little left to take, few enough that each part amortises its
/// workspace.
pub const PARTS_PER_THREAD: usize = 4;

/// The rows of each part when a batch of `rows` is cut for [`for_each_part`]: the whole batch
/// under `serial_below` rows (waking the pool would cost more than the rows), else
/// [`PARTS_PER_THREAD`] parts per thread.
pub fn part_len(rows: usize, serial_below: usize) -> usize {
    if rows < serial_below {
        return rows.max(1);
    }
    rows.div_ceil(threads() * PARTS_PER_THREAD).max(1)
}

/// Runs `work` on every part, the calling thread and the pool's threads claiming one part at a
/// time in order from a shared counter. The caller starts at once, and a pool thread that wakes
/// late (its wake-up costs as much as many rows once the pool has slept between a Python loop's
/// calls) finds fewer parts left, or none, instead of holding the batch up by a fixed share. Serial with
/// one part or one thread. Which thread runs a part never changes its result.
pub fn for_each_part<P: Send>(parts: &mut [P], work: impl Fn(&mut P) + Sync) {
    let helpers = threads().min(parts.len()).saturating_sub(1);
    if helpers == 0 {
        parts.iter_mut().for_each(work);
        return;
    }
    let cells: SmallVec<[Mutex<&mut P>; 32]> = parts.iter_mut().map(Mutex::new).collect();
    let next = AtomicUsize::new(0);
    let claim = || {
        while let Some(cell) = cells.get(next.fetch_add(1, Ordering::Relaxed)) {
            // Each part is claimed once: the lock is never contended (nor poisoned but by a
            // panic in `work`, which the scope propagates anyway).
            let mut part = cell.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            work(&mut part);
        }
    };
    in_place_scope(|scope| match scope {
        Some(scope) => {
            for _ in 0..helpers {
                scope.spawn(|_| claim());
            }
            claim();
        }
        None => claim(),
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_part_runs_once() {
        for len in [0, 1, 2, 7, 64] {
            let mut parts: Vec<(usize, u32)> = (0..len).map(|i| (i, 0)).collect();
            for_each_part(&mut parts, |(i, runs)| {
                *runs += 1;
                *i *= 10;
            });
            assert!(parts
                .iter()
                .enumerate()
                .all(|(k, &(i, runs))| i == 10 * k && runs == 1));
        }
    }
}
