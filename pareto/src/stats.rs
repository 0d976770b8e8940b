//! Latency statistics of repeated timings, and the bootstrap over videos behind the
//! accuracies' standard errors.

use serde::{Deserialize, Serialize};

/// Relative floor of the latency noise: two costs less than 5 % apart are never
/// told apart, however tight the timings (see [`Latency::noise_ms`]).
pub const LATENCY_NOISE_FLOOR: f64 = 0.05;

/// Relative ceiling of the latency noise: two costs more than 15 % apart are told
/// apart, however loaded the machine was while they were timed (see
/// [`Latency::noise_ms`]).
pub const LATENCY_NOISE_CEILING: f64 = 0.15;

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
    /// 10th percentile (nearest rank); 0 in files written before it was recorded.
    #[serde(default)]
    pub p10_ms: f64,
    /// Spread of the runs: half the inter-decile range, `(p90 − p10) / 2`; 0 in files
    /// written before it was recorded.
    #[serde(default)]
    pub spread_ms: f64,
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
        let (p10, p90) = (quantile(&sorted, 0.1)?, quantile(&sorted, 0.9)?);
        Some(Latency {
            median_ms: median,
            p90_ms: p90,
            min_ms: *sorted.first()?,
            runs: sorted.len(),
            p10_ms: p10,
            spread_ms: (p90 - p10) / 2.0,
        })
    }

    /// The cost a variant is charged, on the front and on the device: its fastest
    /// run. On a shared machine other work only ever adds time to a run, so the
    /// fastest run is the one least disturbed; over seven timing passes of the same
    /// models it moved the cheap variant's device cost half as far as the median did
    /// (docs/experiments/2026-11-29-streaming-f1-and-a-budget-sweep.md, section 9).
    pub fn cost_ms(&self) -> f64 {
        self.min_ms
    }

    /// How far apart two costs must be to count as a difference: the spread, but no
    /// less than [`LATENCY_NOISE_FLOOR`] and no more than [`LATENCY_NOISE_CEILING`]
    /// × the cost. Two latencies are within noise when they differ by no more than the
    /// larger of their two noises.
    ///
    /// The ceiling: over 13 timing passes of the default models (2026-11-29 and
    /// -30), the fastest run of a variant, as a share of the reference detector's,
    /// moved from pass to pass by a standard deviation of 3.1 to 10.8 % (median 4.7
    /// %), while the spread of single runs reached 122 % of the cost in passes timed
    /// beside other work. A spread beyond 15 % measures that load, not how far the
    /// fastest run moves; uncapped, two such passes merged every variant into the
    /// most accurate one.
    pub fn noise_ms(&self) -> f64 {
        latency_noise(self.spread_ms, self.cost_ms())
    }
}

/// [`Latency::noise_ms`] from a spread and a cost (ms): the spread clamped to
/// 5-15 % of the cost.
pub fn latency_noise(spread_ms: f64, cost_ms: f64) -> f64 {
    spread_ms
        .min(LATENCY_NOISE_CEILING * cost_ms)
        .max(LATENCY_NOISE_FLOOR * cost_ms)
}

/// Sample standard deviation (divisor `n − 1`); 0 for fewer than two values, and
/// exactly 0 when they are all equal (sums of deviations from the first value).
pub fn std_dev(values: &[f64]) -> f64 {
    let Some(&first) = values.first() else {
        return 0.0;
    };
    if values.len() < 2 {
        return 0.0;
    }
    let n = values.len() as f64;
    let (s1, s2) = values.iter().fold((0.0, 0.0), |(s1, s2), v| {
        let d = v - first;
        (s1 + d, s2 + d * d)
    });
    ((s2 - s1 * s1 / n) / (n - 1.0)).max(0.0).sqrt()
}

/// SplitMix64: a small, fixed, portable generator, so that a seed gives the same
/// resamples on every machine.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (`n > 0`), by rejection, so without modulo bias.
    pub fn below(&mut self, n: usize) -> usize {
        let n = n as u64;
        let zone = u64::MAX - u64::MAX % n;
        loop {
            let x = self.next_u64();
            if x < zone {
                return (x % n) as usize;
            }
        }
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Cluster bootstrap: `resamples` resamples of the items, each drawing as many
/// clusters as there are, with replacement, and taking every item of each drawn
/// cluster. `cluster_of[i]` is item `i`'s cluster (a video). Each resample lists
/// item indices (an item appears once per draw of its cluster). Same seed, same
/// resamples.
pub fn cluster_resamples(cluster_of: &[u32], resamples: usize, seed: u64) -> Vec<Vec<usize>> {
    let mut clusters: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for (i, &c) in cluster_of.iter().enumerate() {
        clusters.entry(c).or_default().push(i);
    }
    let clusters: Vec<Vec<usize>> = clusters.into_values().collect();
    if clusters.is_empty() {
        return Vec::new();
    }
    let mut rng = SplitMix64::new(seed);
    (0..resamples)
        .map(|_| {
            (0..clusters.len())
                .flat_map(|_| clusters[rng.below(clusters.len())].iter().copied())
                .collect()
        })
        .collect()
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

    #[test]
    fn spread_is_half_the_inter_decile_range_with_a_floor_and_a_ceiling() {
        // 1..=20: p10 = 2, p90 = 18 by nearest rank
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        let l = Latency::from_samples(&v).unwrap();
        assert_eq!((l.p10_ms, l.p90_ms, l.spread_ms), (2.0, 18.0, 8.0));
        // a spread of 8 times the fastest run: the 15 % ceiling applies
        assert!((l.noise_ms() - 0.15 * 1.0).abs() < 1e-12);
        // between the two, the spread itself
        let mid = Latency::from_samples(&[10.0, 10.5, 11.0, 11.5, 12.0]).unwrap();
        assert_eq!(mid.spread_ms, 1.0);
        assert_eq!(mid.noise_ms(), 1.0);
        // tight timings: the 5 % floor applies
        let tight = Latency::from_samples(&[10.0, 10.01, 9.99, 10.0]).unwrap();
        assert!(tight.spread_ms < 0.02);
        assert!((tight.noise_ms() - 0.05 * 9.99).abs() < 1e-12);
        assert_eq!(Latency::from_samples(&[4.0]).unwrap().spread_ms, 0.0);
    }

    #[test]
    fn latency_from_a_file_without_the_spread_reads() {
        let l: Latency = serde_json::from_str(
            r#"{"median_ms": 20.0, "p90_ms": 21.0, "min_ms": 19.0, "runs": 9}"#,
        )
        .unwrap();
        assert_eq!((l.p10_ms, l.spread_ms), (0.0, 0.0));
        assert!((l.noise_ms() - 0.95).abs() < 1e-12);
    }

    #[test]
    fn the_cost_is_the_fastest_run_whatever_load_slows_the_others() {
        let quiet = [10.0, 10.2, 10.1, 10.3, 10.0, 10.4];
        let q = Latency::from_samples(&quiet).unwrap();
        // the same runs with half of them slowed by other work on the machine
        let busy: Vec<f64> = quiet
            .iter()
            .enumerate()
            .map(|(i, &ms)| if i % 2 == 1 { ms * 1.6 } else { ms })
            .collect();
        let b = Latency::from_samples(&busy).unwrap();
        assert_eq!((q.cost_ms(), b.cost_ms()), (10.0, 10.0));
        assert!(b.median_ms > q.median_ms + 1.0);
    }

    #[test]
    fn std_dev_matches_hand_computation() {
        assert_eq!(std_dev(&[]), 0.0);
        assert_eq!(std_dev(&[3.0]), 0.0);
        // mean 5, squared deviations 9 + 1 + 1 + 9 = 20, / 3
        assert!((std_dev(&[2.0, 4.0, 6.0, 8.0]) - (20.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(std_dev(&[0.1 + 0.2; 200]), 0.0);
    }

    #[test]
    fn cluster_resamples_draw_whole_clusters_reproducibly() {
        // items 0-2 in video 7, 3-4 in video 1, 5 in video 9
        let clusters = [7, 7, 7, 1, 1, 9];
        let a = cluster_resamples(&clusters, 200, 42);
        assert_eq!(a, cluster_resamples(&clusters, 200, 42));
        assert_ne!(a, cluster_resamples(&clusters, 200, 43));
        assert_eq!(a.len(), 200);
        let members =
            |c: u32| -> Vec<usize> { (0..clusters.len()).filter(|&i| clusters[i] == c).collect() };
        let mut drawn = std::collections::BTreeMap::<u32, usize>::new();
        for r in &a {
            // three draws per resample, each a whole video in order
            let mut rest = &r[..];
            let mut draws = 0;
            while let Some(&first) = rest.first() {
                let m = members(clusters[first]);
                assert_eq!(&rest[..m.len()], &m[..]);
                *drawn.entry(clusters[first]).or_default() += 1;
                rest = &rest[m.len()..];
                draws += 1;
            }
            assert_eq!(draws, 3);
        }
        // every video is drawn about a third of the 600 times
        for (_, n) in drawn {
            assert!((150..=250).contains(&n), "{n}");
        }
        // one video: every resample is the whole set
        assert!(
            cluster_resamples(&[5, 5], 3, 1)
                .iter()
                .all(|r| r == &vec![0, 1])
        );
        assert!(cluster_resamples(&[], 3, 1).is_empty());
    }

    #[test]
    fn splitmix_is_uniform_enough() {
        let mut g = SplitMix64::new(1);
        let mut counts = [0usize; 6];
        for _ in 0..6000 {
            counts[g.below(6)] += 1;
        }
        assert!(
            counts.iter().all(|&c| (900..=1100).contains(&c)),
            "{counts:?}"
        );
        let u: Vec<f64> = (0..1000).map(|_| g.unit()).collect();
        assert!(u.iter().all(|x| (0.0..1.0).contains(x)));
        let mean = u.iter().sum::<f64>() / 1000.0;
        assert!((mean - 0.5).abs() < 0.05);
    }
}
