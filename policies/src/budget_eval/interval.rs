//! How sure a margin is: a paired bootstrap over the scored videos.
//!
//! A margin (the budget policy's sAP@0.5 minus a baseline's, [`super::Margin`]) is
//! measured on a few dozen videos, and which videos were drawn moves it. Each resample
//! draws as many videos as were scored, with replacement, and scores every strategy on
//! the *same* draw (paired): each video's streaming tally (all its clock runs) is
//! pooled over the draw and sAP@0.5 computed as the overall score computes it
//! ([`super::score::pooled_sap50`]). The interval is the central `level` of the
//! resampled margins (percentiles, linearly interpolated). On the full draw, the
//! statistic is the margin itself.
//!
//! The baseline a margin is taken over is fixed by the full sample (the best simple
//! baseline [`super::budget_margins`] names): taking the strongest baseline of each
//! resample instead would bias the margin down by the resamples' noise.
//!
//! It covers the draw of the videos only: the variants' and the tracker's timing,
//! which set the device costs and so the schedules, move a margin between runs as
//! well (the README's re-run bounds).

use super::score::{Margin, SIMPLE, Tally, pooled_sap50};
use super::{BudgetRun, BudgetStrategy};
use crate::budget::BudgetPolicies;
use crate::replay::{ReplayLog, VideoLog};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::collections::hash_map::Entry;

/// Resamples `frugal policy budget` draws.
pub const RESAMPLES: usize = 1000;
/// Central coverage of the interval.
pub const LEVEL: f64 = 0.95;
/// Seed of the draws (the same draws for every budget, strategy and run).
const SEED: u64 = 0x6d61_7267_696e;

/// The budget policy's margins at one budget, each with its interval.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarginInterval {
    /// Central coverage (0.95: from the 2.5th to the 97.5th percentile).
    pub level: f64,
    /// Resamples of the videos.
    pub resamples: usize,
    /// Videos scored (each resample draws as many).
    pub videos: usize,
    /// Over the best simple baseline (the one [`super::Margin::best_baseline`] names):
    /// lower and upper bound, sAP@0.5 (0–1).
    pub best_baseline: [f64; 2],
    /// Over each simple baseline, in [`SIMPLE`] order: lower and upper bound.
    pub versus: Vec<(String, [f64; 2])>,
}

/// Videos drawn with replacement, `resamples` times, `n` a draw (seeded: the same
/// draws every call).
pub(super) fn draws(n: usize, resamples: usize) -> Vec<Vec<usize>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(SEED);
    (0..resamples)
        .map(|_| (0..n).map(|_| rng.random_range(0..n.max(1))).collect())
        .collect()
}

/// The `q` quantile (0–1) of `xs` sorted ascending, linearly interpolated; NaN when
/// empty.
fn quantile(xs: &[f64], q: f64) -> f64 {
    match xs.len() {
        0 => f64::NAN,
        n => {
            let at = q.clamp(0.0, 1.0) * (n - 1) as f64;
            let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
            let w = at - lo as f64;
            xs.get(lo).copied().unwrap_or(f64::NAN) * (1.0 - w)
                + xs.get(hi).copied().unwrap_or(f64::NAN) * w
        }
    }
}

/// Per baseline (name, per-video tallies), the central `level` of the policy's margin
/// over it across `draws` (each a list of indices into the per-video tallies).
pub(super) fn intervals_of<B: AsRef<[Tally]> + Sync>(
    classes: usize,
    policy: &[Tally],
    baselines: &[(String, B)],
    draws: &[Vec<usize>],
    level: f64,
) -> Vec<(String, [f64; 2])> {
    let sap = |tallies: &[Tally], draw: &[usize]| {
        pooled_sap50(classes, draw.iter().filter_map(|&i| tallies.get(i)))
    };
    // per draw, the policy's margin over each baseline
    let margins: Vec<Vec<f64>> = draws
        .par_iter()
        .map(|d| {
            let ours = sap(policy, d);
            baselines
                .iter()
                .map(|(_, t)| ours - sap(t.as_ref(), d))
                .collect()
        })
        .collect();
    let tail = (1.0 - level) / 2.0;
    baselines
        .iter()
        .enumerate()
        .map(|(j, (name, _))| {
            let mut xs: Vec<f64> = margins.iter().filter_map(|m| m.get(j).copied()).collect();
            xs.sort_by(f64::total_cmp);
            (
                name.clone(),
                [quantile(&xs, tail), quantile(&xs, 1.0 - tail)],
            )
        })
        .collect()
}

/// Per video of `videos` (in order), the tally of `runs` on it, its clock runs pooled.
fn per_video(
    log: &ReplayLog,
    videos: &[&VideoLog],
    pol: &BudgetPolicies,
    runs: &[BudgetRun],
) -> Vec<Tally> {
    let forecast = pol.config.forecaster();
    videos
        .iter()
        .map(|v| {
            let arr = v.arrivals_ms(pol.config.fps);
            let mut t = Tally::default();
            for r in runs.iter().filter(|r| r.video == v.id) {
                t.add(&Tally::of(log.classes.max(1), v, &arr, r, forecast));
            }
            t
        })
        .collect()
}

/// Gives each of `margins` ([`super::budget_margins`] of the same runs) its interval:
/// `resamples` paired draws of `videos`, each strategy scored on its runs in `runs`
/// ([`super::stream_all`]'s). A margin whose budget has no budget-policy runs keeps
/// none.
pub fn add_intervals(
    margins: &mut [Margin],
    log: &ReplayLog,
    videos: &[&VideoLog],
    pol: &BudgetPolicies,
    runs: &[(usize, BudgetStrategy, Vec<BudgetRun>)],
    resamples: usize,
) {
    let draws = draws(videos.len(), resamples);
    let classes = log.classes.max(1);
    // runs of equal behaviour are equal ([`super::first_alike`]): each is tallied once
    let alike = super::first_alike_runs(pol, runs);
    let mut tallied: HashMap<usize, Vec<Tally>> = HashMap::new();
    for m in margins {
        let Some(k) = pol.config.budgets_ms.iter().position(|&b| b == m.budget_ms) else {
            continue;
        };
        let mut of = |s: BudgetStrategy| {
            let i = runs.iter().position(|(kk, ss, _)| (*kk, *ss) == (k, s))?;
            let first = alike.get(i).copied().unwrap_or(i);
            let tallies = match tallied.entry(first) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => {
                    let (_, _, rs) = runs.get(first)?;
                    e.insert(per_video(log, videos, pol, rs))
                }
            };
            Some(tallies.clone())
        };
        let Some(policy) = of(BudgetStrategy::Budget) else {
            continue;
        };
        let baselines: Vec<(String, Vec<Tally>)> = SIMPLE
            .iter()
            .filter_map(|&s| of(s).map(|t| (s.name().to_string(), t)))
            .collect();
        let versus = intervals_of(classes, &policy, &baselines, &draws, LEVEL);
        let Some(best_baseline) = versus
            .iter()
            .find(|(n, _)| *n == m.best_baseline)
            .map(|v| v.1)
        else {
            continue;
        };
        m.interval = Some(MarginInterval {
            level: LEVEL,
            resamples,
            videos: videos.len(),
            best_baseline,
            versus,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A video's tally of one class: `hits` of `n` truth boxes found (score 0.9),
    /// `false_boxes` wrong ones (score 0.5).
    fn tally(n: usize, hits: usize, false_boxes: usize) -> Tally {
        let mut recs = vec![(0.9, true); hits];
        recs.extend(vec![(0.5, false); false_boxes]);
        Tally::of_parts(vec![(n, recs)], 0.0, 60)
    }

    fn identity(n: usize) -> Vec<Vec<usize>> {
        vec![(0..n).collect()]
    }

    /// On the full draw the statistic is the margin itself, both bounds.
    #[test]
    fn on_the_full_draw_the_interval_is_the_margin() {
        let ours: Vec<Tally> = (0..6).map(|i| tally(10, 6 + i % 3, 1)).collect();
        let theirs: Vec<Tally> = (0..6).map(|i| tally(10, 5 + i % 2, 2)).collect();
        let want = pooled_sap50(1, ours.iter()) - pooled_sap50(1, theirs.iter());
        assert!(want > 0.0);
        let got = intervals_of(1, &ours, &[("b".into(), theirs)], &identity(6), LEVEL);
        assert_eq!(got.len(), 1);
        for x in got[0].1 {
            assert!((x - want).abs() < 1e-12, "{got:?} against {want}");
        }
    }

    /// A policy ahead on every video has an interval above zero; one far ahead on
    /// half the videos and as far behind on the other half, whose margin is about
    /// zero, has an interval that holds zero and is wider.
    #[test]
    fn a_margin_won_on_every_video_is_sure_and_one_won_on_half_is_not() {
        let n = 24;
        let base: Vec<Tally> = (0..n).map(|_| tally(10, 6, 2)).collect();
        let steady: Vec<Tally> = (0..n).map(|i| tally(10, 7 + i % 3, 2)).collect();
        let split: Vec<Tally> = (0..n)
            .map(|i| {
                if i % 2 == 0 {
                    tally(10, 9, 2)
                } else {
                    tally(10, 3, 2)
                }
            })
            .collect();
        let d = draws(n, 400);
        let one =
            |ours: &[Tally]| intervals_of(1, ours, &[("b".into(), base.clone())], &d, LEVEL)[0].1;
        let sure = one(&steady);
        assert!(sure[0] > 0.0 && sure[0] <= sure[1], "{sure:?}");
        let unsure = one(&split);
        assert!(unsure[0] < 0.0 && unsure[1] > 0.0, "{unsure:?}");
        assert!(
            unsure[1] - unsure[0] > 2.0 * (sure[1] - sure[0]),
            "{sure:?} {unsure:?}"
        );
    }

    #[test]
    fn draws_are_seeded_and_in_range() {
        let (a, b) = (draws(7, 50), draws(7, 50));
        assert_eq!(a, b);
        assert_eq!(a.len(), 50);
        assert!(a.iter().all(|d| d.len() == 7 && d.iter().all(|&i| i < 7)));
        // not every draw is the identity
        assert!(a.iter().any(|d| d.windows(2).any(|w| w[0] == w[1])));
        assert!(draws(0, 3).iter().all(Vec::is_empty));
    }

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let xs = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile(&xs, 0.0), 0.0);
        assert_eq!(quantile(&xs, 1.0), 4.0);
        assert!((quantile(&xs, 0.5) - 2.0).abs() < 1e-12);
        assert!((quantile(&xs, 0.1) - 0.4).abs() < 1e-12);
        assert!(quantile(&[], 0.5).is_nan());
    }
}
