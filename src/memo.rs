//! Results remembered per process, keyed by a hash of their inputs to the bit. One command
//! asks for a record's fits and separations several times (a run's answer, the report of each
//! run, the demo's three runs), and so does one Python session (every run on the same record).

use crate::data::Samples;
use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::sync::Mutex;

/// The last [`Memo::SIZE`] results of a function of hashed inputs. A key is a 64-bit hash: two
/// different inputs share one with odds of about n²/2⁶⁴.
pub(crate) struct Memo<T> {
    entries: Mutex<Vec<(u64, T)>>,
}

impl<T: Clone> Memo<T> {
    /// Results kept; the oldest goes first.
    const SIZE: usize = 8;

    pub(crate) const fn new() -> Self {
        Self {
            entries: Mutex::new(Vec::new()),
        }
    }

    /// The result remembered for `key`, or `work`'s, remembered where it succeeds (a failure
    /// is worked out again when asked again).
    pub(crate) fn get_or_try<E>(&self, key: u64, work: impl FnOnce() -> Result<T, E>) -> Result<T, E> {
        let entries = || self.entries.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, known)) = entries().iter().find(|(k, _)| *k == key) {
            return Ok(known.clone());
        }
        // Not held while working: other threads' lookups go on, and two threads that miss the
        // same key both work it out, to the same result, kept once.
        let worked_out = work()?;
        let mut entries = entries();
        if !entries.iter().any(|(k, _)| *k == key) {
            if entries.len() == Self::SIZE {
                entries.remove(0);
            }
            entries.push((key, worked_out.clone()));
        }
        Ok(worked_out)
    }
}

/// A key of a [`Memo`]: the inputs hashed one after another, floating-point values by their
/// bits.
pub(crate) struct Key(DefaultHasher);

impl Key {
    pub(crate) fn new() -> Self {
        Self(DefaultHasher::new())
    }

    /// A value that hashes itself (names, counts, flags).
    pub(crate) fn value(&mut self, value: impl Hash) -> &mut Self {
        value.hash(&mut self.0);
        self
    }

    /// Numbers to the bit, with their count.
    pub(crate) fn floats(&mut self, values: &[f64]) -> &mut Self {
        values.len().hash(&mut self.0);
        values.iter().for_each(|v| v.to_bits().hash(&mut self.0));
        self
    }

    /// What a fit reads of samples: speeds, torques and weights on bit (not their clock).
    /// Taken apart field by field, so that a field added to [`Samples`] must be placed here or
    /// left out on purpose.
    pub(crate) fn samples(&mut self, samples: &Samples) -> &mut Self {
        let Samples {
            speed_rad_s,
            torque_nm,
            wob_n,
            time_s: _,
        } = samples;
        self.floats(speed_rad_s).floats(torque_nm).value(wob_n.is_some());
        if let Some(wob) = wob_n {
            self.floats(wob);
        }
        self
    }

    pub(crate) fn finish(&self) -> u64 {
        self.0.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_tells_apart_what_it_was_given_to_the_bit() {
        let key = |values: &[f64]| Key::new().floats(values).finish();
        assert_eq!(key(&[1.0, 2.0]), key(&[1.0, 2.0]));
        assert_ne!(key(&[1.0, 2.0]), key(&[1.0, 2.0 + f64::EPSILON * 2.0]));
        assert_ne!(key(&[0.0]), key(&[-0.0]));
        // The count is hashed: a split between two lists moves the key.
        assert_ne!(
            Key::new().floats(&[1.0]).floats(&[2.0, 3.0]).finish(),
            Key::new().floats(&[1.0, 2.0]).floats(&[3.0]).finish()
        );
        let samples = |wob: Option<Vec<f64>>, time: Option<Vec<f64>>| Samples {
            speed_rad_s: vec![1.0, 2.0],
            torque_nm: vec![3.0, 4.0],
            wob_n: wob,
            time_s: time,
        };
        let of = |s: &Samples| Key::new().samples(s).finish();
        // The clock is not read; the weight on bit is.
        assert_eq!(of(&samples(None, None)), of(&samples(None, Some(vec![0.0, 1.0]))));
        assert_ne!(of(&samples(None, None)), of(&samples(Some(vec![5.0, 5.0]), None)));
    }

    #[test]
    fn a_memo_works_out_a_key_once_keeps_the_last_ones_and_forgets_failures() {
        let memo: Memo<u32> = Memo::new();
        let calls = std::cell::Cell::new(0);
        let get = |key: u64, value: Result<u32, ()>| {
            memo.get_or_try(key, || {
                calls.set(calls.get() + 1);
                value
            })
        };
        assert_eq!(get(1, Ok(10)), Ok(10));
        assert_eq!(get(1, Ok(99)), Ok(10), "remembered");
        assert_eq!(get(2, Err(())), Err(()));
        assert_eq!(get(2, Ok(20)), Ok(20), "a failure is worked out again");
        for key in 3..=9 {
            assert_eq!(get(key, Ok(0)), Ok(0));
        }
        // Nine keys asked: the first is the one forgotten.
        assert_eq!(get(2, Ok(99)), Ok(20));
        assert_eq!(get(1, Ok(11)), Ok(11));
        assert_eq!(calls.get(), 11);
    }
}
