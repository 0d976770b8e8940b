//! The hindsight bound (`hindsight`): per video, one fixed (variant, every `N`)
//! schedule of those a budget table may hold (with the tracker and, with
//! [`crate::budget::BudgetConfig::untracked_actions`], without it), chosen knowing the
//! scored videos' own truth, the choices together keeping the budget in device ms per
//! frame over all the videos. No drone can run it. It says how much a scheduler that
//! picks the right schedule for each video could gain over the best fixed schedule on
//! these videos: when the bound itself leads static and static + tracker by little, so
//! must any policy that adapts per video, however good its state.
//!
//! The choice is a coordinate ascent on pooled sAP@0.5: from the better of the given
//! starts (static's and static + tracker's schedules) run on every video, each video in
//! turn takes the schedule (of those a table may hold within the budget's burst,
//! [`crate::budget::BudgetPolicies::table_choices`]) that makes the best start
//! ([`super::search`]'s rule: within the budget first, then the higher pooled
//! sAP@0.5), in sweeps until none changes (at most [`SWEEPS`]). An ascent finds a good
//! choice, not always the best one, so the bound it gives is a lower bound on the best
//! per-video choice; and a policy that changes schedule within a video is not bounded by
//! it.

use super::score::{Tally, ms_per_frame, pooled_sap50};
use super::search::{Figures, better_start};

/// Sweeps over the videos at most.
pub const SWEEPS: usize = 6;

/// The figures of `choice` (per video, an index into its tallies), device ms per frame
/// as the budget charges it ([`super::BudgetRun::charged`]).
fn figures(classes: usize, tallies: &[Vec<Tally>], choice: &[usize]) -> Figures {
    let pick = || tallies.iter().zip(choice).map(|(t, &j)| &t[j]);
    let sap50 = pooled_sap50(classes, pick());
    Figures {
        sap50,
        halves: [sap50; 2],
        ms_per_frame: ms_per_frame(pick()),
    }
}

/// Per video, the index (into `tallies[video]`, one tally per fixed schedule, each
/// pooled over the video's clock runs) of the schedule the bound runs under `budget`,
/// and the figures of that choice: the choice is among `allowed` indices, from the
/// better (as a start, [`better_start`]) of those of `starts` that are allowed, each
/// run on every video (the first allowed index when none is).
pub(super) fn bound(
    classes: usize,
    tallies: &[Vec<Tally>],
    allowed: &[usize],
    starts: &[usize],
    budget: f64,
) -> (Vec<usize>, Figures) {
    // a start must be allowed and held by every video
    let held = |j: &usize| allowed.contains(j) && tallies.iter().all(|t| *j < t.len());
    let first = starts
        .iter()
        .chain(allowed)
        .copied()
        .find(|j| held(j))
        .unwrap_or(0);
    let mut choice = vec![first; tallies.len()];
    let mut cur = figures(classes, tallies, &choice);
    for &j in starts.iter().filter(|j| held(j)) {
        let other = vec![j; tallies.len()];
        let f = figures(classes, tallies, &other);
        if better_start(&f, &cur, budget) {
            choice = other;
            cur = f;
        }
    }
    for _ in 0..SWEEPS {
        let mut changed = false;
        for i in 0..tallies.len() {
            let mut best: Option<(usize, Figures)> = None;
            for &j in allowed {
                if j == choice[i] || j >= tallies[i].len() {
                    continue;
                }
                let keep = choice[i];
                choice[i] = j;
                let f = figures(classes, tallies, &choice);
                choice[i] = keep;
                if better_start(&f, best.as_ref().map_or(&cur, |b| &b.1), budget) {
                    best = Some((j, f));
                }
            }
            if let Some((j, f)) = best {
                choice[i] = j;
                cur = f;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    (choice, cur)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two videos, one class with two truth boxes each; schedule 0 costs 1 ms per frame
    /// and finds one box, schedule 1 costs 3 and finds both.
    fn tallies() -> Vec<Vec<Tally>> {
        let cheap = || Tally::of_parts(vec![(2, vec![(0.9, true), (0.8, false)])], 10.0, 10);
        let dear = |s: f32| Tally::of_parts(vec![(2, vec![(s, true), (s - 0.1, true)])], 30.0, 10);
        vec![vec![cheap(), dear(0.9)], vec![cheap(), dear(0.7)]]
    }

    #[test]
    fn the_bound_takes_the_dear_schedule_where_the_budget_lets_it_and_never_scores_less() {
        let t = tallies();
        let start = figures(1, &t, &[0, 0]);
        // 2 ms per frame: one video of the two can run the dear schedule
        let c = bound(1, &t, &[0, 1], &[0], 2.0).0;
        assert_eq!(c.iter().filter(|&&j| j == 1).count(), 1, "{c:?}");
        let f = figures(1, &t, &c);
        assert!(f.ms_per_frame <= 2.0 + 1e-12);
        assert!(f.sap50 > start.sap50, "{} vs {}", f.sap50, start.sap50);
        // 3 ms: both
        assert_eq!(bound(1, &t, &[0, 1], &[0], 3.0).0, vec![1, 1]);
        // 1 ms, or the dear schedule not allowed: the start
        assert_eq!(bound(1, &t, &[0, 1], &[0], 1.0).0, vec![0, 0]);
        assert_eq!(bound(1, &t, &[0], &[0], 3.0).0, vec![0, 0]);
    }

    #[test]
    fn from_a_start_over_the_budget_the_bound_comes_down_to_it() {
        let t = tallies();
        // start dear everywhere (3 ms) under 2 ms: one video comes down to 1 ms
        let c = bound(1, &t, &[0, 1], &[1], 2.0).0;
        assert!(figures(1, &t, &c).ms_per_frame <= 2.0 + 1e-12, "{c:?}");
        // nothing keeps 0.5 ms: the cheapest choice
        assert_eq!(bound(1, &t, &[0, 1], &[1], 0.5).0, vec![0, 0]);
        // no videos, nothing to choose
        assert!(bound(1, &[], &[0, 1], &[0], 2.0).0.is_empty());
    }

    #[test]
    fn the_bound_starts_from_the_better_of_its_starts() {
        let t = tallies();
        // under 3 ms the dear schedule is the better start, and nothing beats it
        assert_eq!(bound(1, &t, &[0, 1], &[0, 1], 3.0).0, vec![1, 1]);
        // a start that is not allowed is passed over
        assert_eq!(bound(1, &t, &[0], &[0, 1], 3.0).0, vec![0, 0]);
        // under 1 ms only the cheap one keeps the budget
        assert_eq!(bound(1, &t, &[0, 1], &[1, 0], 1.0).0, vec![0, 0]);
        // a start no video holds is passed over; no start: the first allowed
        assert_eq!(bound(1, &t, &[0, 1], &[7], 1.0).0, vec![0, 0]);
        assert_eq!(bound(1, &t, &[1], &[], 3.0).0, vec![1, 1]);
    }
}
