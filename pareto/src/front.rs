//! Pareto fronts over (accuracy ↑, latency ↓), and who dominates whom.

/// One candidate on the accuracy-latency plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Accuracy, higher is better (mAP@0.5, F1 or mean IoU).
    pub accuracy: f64,
    /// Latency, lower is better (milliseconds).
    pub latency: f64,
}

impl Point {
    /// `self` dominates `other`: at least as accurate and at least as fast, and strictly
    /// better in one of the two.
    pub fn dominates(&self, other: &Point) -> bool {
        self.accuracy >= other.accuracy
            && self.latency <= other.latency
            && (self.accuracy > other.accuracy || self.latency < other.latency)
    }
}

/// Indices of the non-dominated points, sorted by latency (fastest first). Points with
/// a NaN coordinate are never on the front. Exact duplicates are all kept.
///
/// Runs in O(n log n): sort by latency (ties: most accurate first) and sweep, keeping a
/// point when it is more accurate than every faster one.
pub fn front(points: &[Point]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| !points[i].accuracy.is_nan() && !points[i].latency.is_nan())
        .collect();
    order.sort_by(|&a, &b| {
        points[a]
            .latency
            .total_cmp(&points[b].latency)
            .then(points[b].accuracy.total_cmp(&points[a].accuracy))
    });
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        let p = points[i];
        match kept.last().map(|&k| points[k]) {
            None => kept.push(i),
            Some(last) if p == last => kept.push(i),
            Some(last) if p.accuracy > last.accuracy => kept.push(i),
            Some(_) => {}
        }
    }
    // A kept point could still be dominated by an equally fast, more accurate point
    // kept before it only when latencies tie; the sort puts the more accurate first, so
    // such a point fails the `p.accuracy > last.accuracy` test above. Nothing to fix.
    kept
}

/// For each point, the indices of the points that dominate it (empty on the front).
pub fn dominators(points: &[Point]) -> Vec<Vec<usize>> {
    points
        .iter()
        .map(|p| {
            points
                .iter()
                .enumerate()
                .filter(|(_, q)| q.dominates(p))
                .map(|(j, _)| j)
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(points: &[Point]) -> Vec<usize> {
        let mut on: Vec<usize> = (0..points.len())
            .filter(|&i| {
                !points[i].accuracy.is_nan()
                    && !points[i].latency.is_nan()
                    && !points.iter().any(|q| q.dominates(&points[i]))
            })
            .collect();
        on.sort_by(|&a, &b| {
            points[a]
                .latency
                .total_cmp(&points[b].latency)
                .then(points[b].accuracy.total_cmp(&points[a].accuracy))
                .then(a.cmp(&b))
        });
        on
    }

    fn p(accuracy: f64, latency: f64) -> Point {
        Point { accuracy, latency }
    }

    #[test]
    fn hand_made_front() {
        let pts = [
            p(0.9, 10.0),
            p(0.8, 5.0),
            p(0.85, 12.0),
            p(0.5, 1.0),
            p(0.5, 2.0),
        ];
        assert_eq!(front(&pts), vec![3, 1, 0]);
        let dom = dominators(&pts);
        assert_eq!(dom[2], vec![0]);
        assert_eq!(dom[4], vec![3]);
        assert!(dom[0].is_empty());
    }

    proptest! {
        #[test]
        fn front_matches_brute_force(raw in prop::collection::vec((0u8..20, 0u8..20), 0..60)) {
            // Small integer grids make ties and duplicates common.
            let pts: Vec<Point> = raw.iter().map(|&(a, l)| p(a as f64 / 20.0, l as f64)).collect();
            let mut fast = front(&pts);
            let mut slow = brute_force(&pts);
            fast.sort_unstable();
            slow.sort_unstable();
            prop_assert_eq!(fast, slow);
        }
    }
}
