//! Timing harness: warm-up runs, then timed runs, summarised as [`Latency`].

use crate::stats::Latency;
use std::time::Instant;

/// Run `f` `warmup` times untimed, then `runs` times timed (each call timed on its
/// own, wall clock), and summarise. Stops at the first error.
pub fn measure<E>(
    warmup: usize,
    runs: usize,
    mut f: impl FnMut(usize) -> Result<(), E>,
) -> Result<Option<Latency>, E> {
    for i in 0..warmup {
        f(i)?;
    }
    let mut samples = Vec::with_capacity(runs);
    for i in 0..runs {
        let t = Instant::now();
        f(warmup + i)?;
        samples.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(Latency::from_samples(&samples))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_warmup_and_timed_calls_and_stops_on_error() {
        let mut calls = Vec::new();
        let l = measure::<()>(2, 5, |i| {
            calls.push(i);
            Ok(())
        })
        .unwrap()
        .unwrap();
        assert_eq!(calls, vec![0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(l.runs, 5);
        assert!(l.min_ms <= l.median_ms && l.median_ms <= l.p90_ms);
        let r = measure(1, 5, |i| if i == 3 { Err(i) } else { Ok(()) });
        assert_eq!(r, Err(3));
        assert_eq!(measure::<()>(0, 0, |_| Ok(())), Ok(None));
    }
}
