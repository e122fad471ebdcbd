//! Locks that outlive a panicking holder.

use std::sync::{Mutex, MutexGuard, PoisonError};

/// Lock `m`, taking the data as it is when a thread panicked while holding it.
///
/// For state that a panic cannot leave half-updated in a way that matters: counters
/// (still the best there are), handle lists and queues edited one push or swap at a
/// time. Such a lock stays usable instead of failing every later caller.
pub fn lock<T: ?Sized>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_poisoned_lock_still_gives_its_data() {
        let m = Mutex::new(vec![1]);
        let _ = std::thread::scope(|s| {
            s.spawn(|| {
                let mut g = lock(&m);
                g.push(2);
                panic!("holder dies");
            })
            .join()
        });
        assert!(m.is_poisoned());
        lock(&m).push(3);
        assert_eq!(*lock(&m), vec![1, 2, 3]);
    }
}
