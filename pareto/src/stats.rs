//! Latency statistics of repeated timings.

use serde::{Deserialize, Serialize};

/// Summary of repeated timings, in milliseconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Latency {
    /// Median.
    pub median_ms: f64,
    /// 90th percentile (nearest rank).
    pub p90_ms: f64,
    /// Fastest run.
    pub min_ms: f64,
    /// How many timed runs.
    pub runs: usize,
}

/// The `q`-quantile (0..=1) of sorted samples by nearest rank; `None` when empty.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize;
    sorted
        .get(rank.saturating_sub(1).min(sorted.len() - 1))
        .copied()
}

impl Latency {
    /// Summarise samples (milliseconds); `None` when there are none or one is NaN.
    pub fn from_samples(samples: &[f64]) -> Option<Latency> {
        if samples.is_empty() || samples.iter().any(|s| s.is_nan()) {
            return None;
        }
        let mut sorted = samples.to_vec();
        sorted.sort_by(f64::total_cmp);
        let median = if sorted.len() % 2 == 1 {
            quantile(&sorted, 0.5)?
        } else {
            let hi = sorted.len() / 2;
            (sorted.get(hi - 1)? + sorted.get(hi)?) / 2.0
        };
        Some(Latency {
            median_ms: median,
            p90_ms: quantile(&sorted, 0.9)?,
            min_ms: *sorted.first()?,
            runs: sorted.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_p90() {
        let l =
            Latency::from_samples(&[5.0, 1.0, 3.0, 2.0, 4.0, 10.0, 6.0, 7.0, 8.0, 9.0]).unwrap();
        assert_eq!(l.median_ms, 5.5);
        assert_eq!(l.p90_ms, 9.0);
        assert_eq!(l.min_ms, 1.0);
        assert_eq!(
            Latency::from_samples(&[2.0, 1.0, 3.0]).unwrap().median_ms,
            2.0
        );
        assert!(Latency::from_samples(&[]).is_none());
        assert!(Latency::from_samples(&[1.0, f64::NAN]).is_none());
    }
}
