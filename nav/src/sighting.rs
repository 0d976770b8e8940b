//! Turn and STOP signs read ahead and placed on the odometer ([`Sighting`]): how
//! readings of one sign accumulate support, when a sighting is trusted enough to act
//! on, and which detections count as readings at all.
use frugal_data::NavAction;
use frugal_runtime::Detection;

/// A turn or STOP sign read ahead: its action, where it stands on the odometer, the
/// last distance read, and its support: +1 per agreeing reading, × [`SUPPORT_DECAY`]
/// per processed frame that neither reads it nor carries a tracked box onto it, so
/// only a sign read on most recent detection frames reaches `confirm_frames`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sighting {
    pub(crate) action: NavAction,
    pub(crate) at: f64,
    pub(crate) dist: f64,
    /// The renderer's depth of the sign under the last reading's box, when its box
    /// overlaps one: not used to navigate, only to report how far off a reading was.
    pub(crate) true_dist: Option<f64>,
    pub(crate) support: f64,
    /// The highest support reached; a sighting that reached `confirm_frames` is
    /// kept (and acted on) even when the sign is no longer readable close up.
    pub(crate) peak: f64,
    /// Confirmed by the perception's most accurate detector ([`Perception::confirm`]),
    /// or by its readings alone when it has nothing more accurate: only a verified
    /// sighting is acted on.
    ///
    /// [`Perception::confirm`]: crate::Perception::confirm
    pub(crate) verified: bool,
    /// Its action was read by the most accurate detector: readings of any turn or STOP
    /// at its spot support it (a cheap detector that mirrors an arrow steadily still
    /// places it right).
    pub(crate) settled: bool,
    /// The most accurate detector's readings of it so far, by action
    /// ([`action_index`]): re-read every [`RECONFIRM_EVERY`] metres while it is
    /// approached, the majority decides its action (one accurate reading of a small
    /// far arrow can be mirrored too).
    pub(crate) votes: [f64; 4],
    /// Re-readings by the most accurate detector that found no turn or STOP sign at its
    /// spot. A sign it once read can be missed on a frame, so one such reading abstains;
    /// but once they outnumber the votes of its action, the first reading was a false
    /// alarm and the sighting is dropped (without this rule, a confirmed false "turn
    /// left" on a wall, never read again over 2.4 m, turned the drone into that wall;
    /// rule added in a931b6b).
    pub(crate) blanks: f64,
    /// Odometer at its last confirmation.
    pub(crate) confirmed_at: f64,
    /// A tracker carried a box onto it this frame: its support does not fade.
    pub(crate) held: bool,
    /// Least-squares fit of the distance read against the odometer over the
    /// sighting's readings: a sign that stands still comes closer by as much as the
    /// drone flies (slope −1). A far sign whose box a detector cannot draw small enough
    /// is read at the same distance however far the drone flies (slope ≈ 0): its spot
    /// moves with the drone, and acting on it turns the drone metres early.
    pub(crate) fit: LineFit,
}

/// Per-frame decay of a sighting's support.
pub(crate) const SUPPORT_DECAY: f64 = 0.8;
/// A sighting is acted on only once its readings span this much flight, metres …
const MIN_SPAN: f64 = 0.5;
/// … and its distance shrinks at least this fast per metre flown.
const MIN_APPROACH: f64 = 0.5;
/// Readings spanning this much flight whose distance shrinks slower than
/// [`RESTART_APPROACH`] per metre flown: the spot has moved with the drone, and the
/// sighting starts again from the latest reading (a far sign read too close, then
/// really approached, is not held back by its early readings).
const RESTART_SPAN: f64 = 1.0;
/// See [`RESTART_SPAN`].
const RESTART_APPROACH: f64 = 0.25;
/// A confirmed sign is read again by the most accurate detector every this many
/// metres flown until the drone acts on it.
pub(crate) const RECONFIRM_EVERY: f64 = 1.0;

/// One reading per sign: a detection is dropped when a higher-scoring one of any class
/// covers the same box (IoU ≥ 0.5). The detectors suppress overlaps per class, so a
/// WAIT pictogram can come back as WAIT at 0.9 and as a turn at 0.55; without this,
/// a confirmation found the turn among the reference detector's boxes and the drone
/// turned 21 m early into a wall (hard maze, tx2-like device; fixed in a09cb98).
pub(crate) fn outranked_dropped(detections: &[Detection]) -> impl Iterator<Item = &Detection> {
    detections.iter().filter(move |d| {
        !detections
            .iter()
            .any(|e| e.score > d.score && e.bbox.iou(&d.bbox) >= 0.5)
    })
}

/// How far apart (metres) two readings of a sign `dist` ahead may place it and still
/// be the same sign: box heights are read to about 15 %.
pub(crate) fn spot_tolerance(dist: f64) -> f64 {
    0.5 + 0.15 * dist
}

fn action_index(a: NavAction) -> usize {
    match a {
        NavAction::TurnLeft => 0,
        NavAction::TurnRight => 1,
        NavAction::Stop => 2,
        NavAction::Wait => 3,
    }
}

/// Running least-squares line through (odometer, distance read) points.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct LineFit {
    pub(crate) n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    x_min: f64,
    pub(crate) x_max: f64,
}

impl LineFit {
    fn new(x: f64, y: f64) -> Self {
        let mut f = Self {
            x_min: x,
            x_max: x,
            ..Self::default()
        };
        f.add(x, y);
        f
    }

    fn add(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.sxy += x * y;
        self.x_min = self.x_min.min(x);
        self.x_max = self.x_max.max(x);
    }

    /// Odometer span of the points, metres.
    pub(crate) fn span(&self) -> f64 {
        self.x_max - self.x_min
    }

    /// How fast the distance read shrinks per metre flown (1 for a sign standing
    /// still); `None` with fewer than two distinct odometer readings.
    pub(crate) fn approach(&self) -> Option<f64> {
        let var = self.n * self.sxx - self.sx * self.sx;
        (var > 1e-9 * self.n * self.n).then(|| -(self.n * self.sxy - self.sx * self.sy) / var)
    }
}

impl Sighting {
    pub(crate) fn new(action: NavAction, odo: f64, dist: f64, true_dist: Option<f64>) -> Self {
        Self {
            action,
            at: odo + dist,
            dist,
            true_dist,
            support: 1.0,
            peak: 1.0,
            verified: false,
            settled: false,
            votes: [0.0; 4],
            blanks: 0.0,
            confirmed_at: f64::NEG_INFINITY,
            held: false,
            fit: LineFit::new(odo, dist),
        }
    }

    /// Another reading of this sign, `dist` ahead at odometer `odo` (`true_dist`: see
    /// [`Sighting::true_dist`]).
    pub(crate) fn read(&mut self, odo: f64, dist: f64, true_dist: Option<f64>) {
        self.fit.add(odo, dist);
        if self.fit.span() >= RESTART_SPAN
            && self.fit.approach().is_some_and(|a| a < RESTART_APPROACH)
        {
            *self = Self::new(self.action, odo, dist, true_dist);
            return;
        }
        self.support += 1.0;
        self.peak = self.peak.max(self.support);
        self.at = odo + dist; // the closer reading is the better one
        self.dist = dist;
        self.true_dist = true_dist;
    }

    /// A tracker carried a box onto it ([`Percept::tracked`](crate::Percept::tracked)):
    /// the sign is still in view, so its support does not fade this frame. The box is
    /// the tracker's prediction from the last detection, not a new reading: it adds no
    /// support (a weak false detection carried for `M` frames would otherwise build
    /// the support of a measured sign and be confirmed), and its size does not place
    /// the sign.
    pub(crate) fn hold(&mut self) {
        self.held = true;
    }

    /// The most accurate detector read it as `action`, `dist` ahead at `odo`: a vote,
    /// and the majority of the votes is its action (a tie goes to this reading).
    pub(crate) fn confirmed(
        &mut self,
        action: NavAction,
        odo: f64,
        dist: f64,
        true_dist: Option<f64>,
    ) {
        self.read(odo, dist, true_dist);
        self.votes[action_index(action)] += 1.0;
        let mine = self.votes[action_index(action)];
        if self.votes[action_index(self.action)] <= mine {
            self.action = action;
        }
        self.verified = true;
        self.settled = true;
        self.confirmed_at = odo;
    }

    /// Read over enough flight to tell, and coming closer as a standing sign does.
    pub(crate) fn stands_still(&self) -> bool {
        self.fit.span() >= MIN_SPAN && self.fit.approach().is_some_and(|a| a >= MIN_APPROACH)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frugal_data::Sign;

    #[test]
    fn a_sign_read_as_two_classes_counts_once_as_its_best_class() {
        use frugal_runtime::BBox;
        let det = |class: Sign, score: f32, x: f32| Detection {
            bbox: BBox::new(x, 100.0, x + 24.0, 124.0),
            score,
            class: class.id(),
        };
        // the WAIT pictogram, also read as a turn at a lower score (per-class NMS
        // keeps both), and a real turn sign elsewhere in the frame
        let dets = [
            det(Sign::TurnRight, 0.55, 101.0),
            det(Sign::Wait, 0.9, 100.0),
            det(Sign::TurnRight, 0.6, 300.0),
        ];
        let kept: Vec<(Option<Sign>, f32)> = outranked_dropped(&dets)
            .map(|d| (Sign::from_id(d.class), d.score))
            .collect();
        assert_eq!(
            kept,
            vec![(Some(Sign::Wait), 0.9), (Some(Sign::TurnRight), 0.6)]
        );
        // boxes that merely touch are two signs
        let apart = [
            det(Sign::Wait, 0.9, 100.0),
            det(Sign::TurnRight, 0.55, 118.0),
        ];
        assert_eq!(outranked_dropped(&apart).count(), 2);
    }
}
