//! Reusable scratch values shared by concurrent callers: a few slots, each behind its own lock
//! on its own cache line, every thread trying its own slot first. One lock around a shared
//! pool made two threads stepping a vector environment's worlds wait on each other at every
//! row (the shield's part of a 64-world step took longer on two threads than on one).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, TryLockError};

/// Slots per owner: more than the threads that call at once on the machines we run on; a
/// caller that finds every slot busy makes a value of its own for the call.
const SLOTS: usize = 8;

static NEXT_THREAD: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// This thread's first slot (threads are numbered as they first call).
    static HOME: usize = NEXT_THREAD.fetch_add(1, Ordering::Relaxed) % SLOTS;
}

/// One slot, alone on its cache line (two threads' slots never share one).
#[repr(align(128))]
#[derive(Default)]
struct Slot<T>(Mutex<Option<T>>);

/// Scratch values of type `T` for concurrent callers (see the module docs).
pub struct Slots<T> {
    slots: [Slot<T>; SLOTS],
}

impl<T> Default for Slots<T> {
    fn default() -> Self {
        Slots {
            slots: std::array::from_fn(|_| Slot(Mutex::new(None))),
        }
    }
}

impl<T> Slots<T> {
    /// Runs `run` on a free slot's value (made by `make` the first time), else on a value of
    /// its own.
    pub fn with<R>(&self, make: impl FnOnce() -> T, run: impl FnOnce(&mut T) -> R) -> R {
        let home = HOME.with(|h| *h);
        for k in 0..SLOTS {
            let slot = &self.slots[(home + k) % SLOTS].0;
            let mut guard = match slot.try_lock() {
                Ok(guard) => guard,
                // A panic while the slot was held: the value is scratch, reuse it.
                Err(TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
                Err(TryLockError::WouldBlock) => continue,
            };
            return run(guard.get_or_insert_with(make));
        }
        run(&mut make())
    }
}

impl<T> std::fmt::Debug for Slots<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Slots")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_is_made_once_per_slot_and_reused() {
        let slots = Slots::default();
        let mut made = 0;
        for _ in 0..5 {
            slots.with(
                || {
                    made += 1;
                    Vec::<u8>::new()
                },
                |v| v.push(1),
            );
        }
        assert_eq!(made, 1);
        assert_eq!(slots.with(Vec::new, |v| v.len()), 5);
    }

    #[test]
    fn concurrent_callers_each_get_a_value() {
        let slots = Slots::<Vec<usize>>::default();
        std::thread::scope(|scope| {
            for t in 0..12 {
                let slots = &slots;
                scope.spawn(move || {
                    for _ in 0..100 {
                        slots.with(Vec::new, |v| {
                            v.clear();
                            v.push(t);
                            assert_eq!(v, &[t]);
                        });
                    }
                });
            }
        });
    }
}
