//! The navigator as a step function ([`Navigator::step`]): per processed frame, the
//! time, the distance flown, whether the last turn is over, whether a pedestrian is
//! close and the frame's sign detections go in; a [`NavCommand`] (or none) comes out.
//! The maze simulator and the drone-side program run this same code.
use crate::config::{NavConfig, NavDistances};
use crate::sighting::{
    RECONFIRM_EVERY, SUPPORT_DECAY, Sighting, outranked_dropped, spot_tolerance,
};
use frugal_data::{NavAction, Sign};
use frugal_runtime::{BBox, Detection};

/// The navigator's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Flying along the corridor.
    Cruise,
    /// Hovering while a pedestrian is in view in a WAIT zone.
    HoldForPedestrian,
    /// Turning in place towards a new heading.
    Turning,
    /// Hovering at a WAIT sign.
    Waiting,
    /// Landed (or crashed); the flight is over.
    Done,
}

/// What the navigator tells the vehicle to do, on the frame where it decides it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NavCommand {
    /// Turn a quarter turn to the left in place, then fly on.
    TurnLeft,
    /// Turn a quarter turn to the right in place, then fly on.
    TurnRight,
    /// Land here (a STOP sign).
    Land,
    /// Stop and hover (a WAIT sign, or a pedestrian close in a WAIT zone).
    Hold,
    /// Fly on after a hold.
    Resume,
}

impl NavCommand {
    /// The command's name as the JSON output spells it (`turn_left`, `land`, …).
    pub fn name(self) -> &'static str {
        match self {
            NavCommand::TurnLeft => "turn_left",
            NavCommand::TurnRight => "turn_right",
            NavCommand::Land => "land",
            NavCommand::Hold => "hold",
            NavCommand::Resume => "resume",
        }
    }
}

/// One confirmation of a sighting by the most accurate detector, next to what a
/// ground truth (the simulator's renderer) knows, when there is one.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConfirmationRead {
    /// Time, s.
    pub t: f64,
    /// The sighting's action before this reading.
    pub sighting: NavAction,
    /// The turn or STOP sign read at the sighting's spot (`None`: none there).
    pub read: Option<NavAction>,
    /// Its distance from its box height, metres.
    pub read_m: Option<f64>,
    /// What the sign under the read box (the one it overlaps most) tells the drone to do …
    pub truth: Option<NavAction>,
    /// … and its depth, metres.
    pub true_m: Option<f64>,
}

/// The camera and the signs, as the navigator needs them to tell distances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// Image width, pixels.
    pub width: u32,
    /// Focal length, pixels.
    pub focal_px: f64,
    /// Height of a sign board, metres.
    pub sign_size: f64,
}

/// What the navigator is given for one processed frame.
#[derive(Clone, Copy, Debug)]
pub struct NavInput<'a> {
    /// Time of the decision, seconds.
    pub t: f64,
    /// Distance flown so far, metres (the autopilot's odometry, or dead reckoning).
    pub odometer: f64,
    /// The last turn the navigator ordered is over (read only while turning).
    pub turn_done: bool,
    /// A pedestrian is in view closer than [`NavConfig::pedestrian_distance`].
    pub pedestrian_close: bool,
    /// The frame's sign detections, in image pixels.
    pub detections: &'a [Detection],
    /// The detections are boxes a tracker carried, not measured on this frame.
    pub tracked: bool,
}

/// What a step produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NavStep {
    /// The command decided on this frame, if any.
    pub command: Option<NavCommand>,
    /// What the navigator did, for people (`turn left (last read at 1.02 m; …)`).
    pub events: Vec<String>,
    /// Confirmation readings asked on this frame.
    pub reads: Vec<ConfirmationRead>,
}

/// The sign under a box, as a ground truth knows it: its class id and depth, metres.
pub type Truth<'a> = &'a dyn Fn(&BBox) -> Option<(u16, f64)>;

/// What the drone does on `class`, by the table `actions` (past its end: nothing).
fn meaning(actions: &[Option<NavAction>], class: u16) -> Option<NavAction> {
    actions.get(usize::from(class)).copied().flatten()
}

/// The sign-to-action navigator (see the [crate documentation](crate)).
#[derive(Clone, Debug)]
pub struct Navigator {
    nav: NavConfig,
    dist: NavDistances,
    optics: Optics,
    mode: Mode,
    turn_armed_at: f64,
    wait_zone_until: f64,
    wait_started: f64,
    streak: Option<(NavAction, u32)>,
    // turn and STOP signs read ahead, placed on the odometer
    sightings: Vec<Sighting>,
    confirmations: u64,
    rejections: u64,
    /// What the drone does on each class, by class id.
    actions: Vec<Option<NavAction>>,
}

/// ", truly X m" for an event, when a ground truth knows the distance.
fn truly(true_dist: Option<f64>) -> String {
    true_dist.map_or_else(String::new, |d| format!(", truly {d:.2} m"))
}

impl Navigator {
    /// A navigator cruising, with `nav`'s parameters resolved for a corridor grid of
    /// `cell` metres.
    pub fn new(nav: &NavConfig, cell: f64, optics: Optics) -> Self {
        Self {
            nav: nav.clone(),
            dist: nav.distances(cell),
            optics,
            mode: Mode::Cruise,
            turn_armed_at: 0.0,
            wait_zone_until: f64::NEG_INFINITY,
            wait_started: 0.0,
            streak: None,
            sightings: Vec::new(),
            confirmations: 0,
            rejections: 0,
            actions: Sign::ALL.iter().map(|s| s.action()).collect(),
        }
    }

    /// What the drone does on each class, by class id (`None`: nothing); classes past
    /// the end mean nothing. The default is the ten synthetic signs' meanings; a
    /// detector of other classes needs its own table (a dataset's
    /// [`ClassInfo::action`](frugal_data::ClassInfo::action)s in class order).
    pub fn with_actions(mut self, actions: Vec<Option<NavAction>>) -> Self {
        self.actions = actions;
        self
    }

    /// The meaning of class `class`.
    pub fn action_of(&self, class: u16) -> Option<NavAction> {
        meaning(&self.actions, class)
    }

    /// The current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The resolved distances.
    pub fn distances(&self) -> NavDistances {
        self.dist
    }

    /// Confirmation readings received so far (those `confirm` answered with `Some`).
    pub fn confirmations(&self) -> u64 {
        self.confirmations
    }

    /// Confirmations that dropped a sighting on its first reading.
    pub fn rejections(&self) -> u64 {
        self.rejections
    }

    /// How far a detection's sign is, from its box height, metres.
    pub fn distance_of(&self, d: &Detection) -> f64 {
        self.optics.focal_px * self.optics.sign_size / f64::from(d.bbox.height()).max(1e-3)
    }

    /// Decide on one processed frame.
    ///
    /// `confirm` reads the frame again with the most accurate detector (the bundle's
    /// reference variant) before a sign is acted on: `Ok(None)` when there is nothing
    /// more accurate than what produced `input.detections`, so their readings stand.
    /// `truth` names the sign under a box for the events and the confirmation reads
    /// (the simulator's renderer); it is never used to navigate.
    pub fn step<E>(
        &mut self,
        input: &NavInput<'_>,
        mut confirm: impl FnMut() -> Result<Option<Vec<Detection>>, E>,
        truth: Truth<'_>,
    ) -> Result<NavStep, E> {
        let mut out = NavStep::default();
        let prev_mode = self.mode;
        let (t, odo) = (input.t, input.odometer);
        let nav = &self.nav;
        let NavDistances {
            turn: turn_distance,
            land: land_distance,
            commit: commit_distance,
            wait_zone: zone_length,
            rearm,
        } = self.dist;
        let optics = self.optics;
        let mut landed = false;
        let mut turned = None;
        match self.mode {
            Mode::Turning => {
                if input.turn_done {
                    self.mode = Mode::Cruise;
                    self.turn_armed_at = odo + rearm;
                }
            }
            Mode::Waiting => {
                if t - self.wait_started >= nav.wait_min_s && !input.pedestrian_close {
                    self.mode = Mode::Cruise;
                    self.wait_zone_until = odo + zone_length;
                    out.events.push("resume: WAIT zone clear".into());
                }
            }
            Mode::Cruise | Mode::HoldForPedestrian => {
                self.mode = Mode::Cruise;
                let (turn_armed_at, wait_zone_until) = (self.turn_armed_at, self.wait_zone_until);
                let actions = &self.actions;
                // what a detection would make the drone do, and how far away the sign is
                let reading = |d: &Detection| {
                    let action = meaning(actions, d.class)?;
                    let dist =
                        optics.focal_px * optics.sign_size / f64::from(d.bbox.height()).max(1e-3);
                    let (cx, _) = d.bbox.center();
                    let centred = (f64::from(cx) - f64::from(optics.width) / 2.0).abs()
                        <= nav.centre_band * f64::from(optics.width);
                    let acts = match action {
                        NavAction::Stop => centred && dist <= commit_distance,
                        NavAction::TurnLeft | NavAction::TurnRight => {
                            centred && dist <= commit_distance && odo >= turn_armed_at
                        }
                        NavAction::Wait => dist <= nav.wait_distance && odo >= wait_zone_until,
                    };
                    acts.then_some((action, dist))
                };
                // the first detection this frame that would make the drone act …
                let candidate = outranked_dropped(input.detections)
                    .find_map(|d| reading(d).map(|(action, dist)| (action, dist, d.bbox)));
                let need = nav.confirm_frames.max(1);
                match candidate {
                    Some((NavAction::Wait, dist, _)) => {
                        // … a WAIT sign after `need` frames in a row …
                        self.streak = match self.streak {
                            Some((NavAction::Wait, n)) => Some((NavAction::Wait, n + 1)),
                            _ => Some((NavAction::Wait, 1)),
                        };
                        if self.streak.is_some_and(|(_, n)| n >= need) {
                            self.mode = Mode::Waiting;
                            self.wait_started = t;
                            self.streak = None;
                            out.events
                                .push(format!("stop at WAIT (estimated {dist:.2} m)"));
                        }
                    }
                    // … a turn or STOP sign is placed on the odometer, where readings
                    // of it accumulate
                    Some((action, dist, bbox)) => {
                        self.streak = None;
                        let at = odo + dist;
                        let tol = spot_tolerance(dist);
                        let true_dist = || truth(&bbox).map(|(_, depth)| depth);
                        match self
                            .sightings
                            .iter_mut()
                            .find(|s| (s.action == action || s.settled) && (s.at - at).abs() <= tol)
                        {
                            // a carried box holds a sighting's support but adds none,
                            // and neither places nor starts a sighting: it repeats the
                            // last detection (a weak false one would build support
                            // frame after frame) and its size is the tracker's
                            // prediction (a box stuck at one size close up would push
                            // the manoeuvre ahead of the drone)
                            Some(s) if input.tracked => s.hold(),
                            Some(s) => s.read(odo, dist, true_dist()),
                            None if input.tracked => {}
                            None => {
                                self.sightings
                                    .push(Sighting::new(action, odo, dist, true_dist()))
                            }
                        }
                    }
                    None => self.streak = None,
                }
                let need_f = f64::from(need);
                let trigger_of = |s: &Sighting| {
                    if s.action == NavAction::Stop {
                        land_distance
                    } else {
                        turn_distance
                    }
                };
                // a sighting that has just built enough support is read again by the
                // perception's most accurate detector before anything is scheduled on
                // it (one per frame), and again every RECONFIRM_EVERY metres until it
                // is due: the majority of its readings at the same spot decides the
                // action; where the first reads no turn or STOP sign, the sighting is
                // dropped
                if let Some(i) = self.sightings.iter().position(|s| {
                    s.peak >= need_f
                        && (!s.verified
                            || (s.settled
                                && odo - s.confirmed_at >= RECONFIRM_EVERY
                                && odo < s.at - trigger_of(s)))
                }) {
                    match confirm()? {
                        None => self
                            .sightings
                            .iter_mut()
                            .filter(|s| s.peak >= need_f)
                            .for_each(|s| s.verified = true),
                        Some(check) => {
                            self.confirmations += 1;
                            let s = &mut self.sightings[i];
                            let tol = |dist: f64| spot_tolerance(dist.max(s.dist));
                            let agrees = outranked_dropped(&check)
                                .filter_map(|d| reading(d).map(|r| (r, d.bbox)))
                                .find(|&((action, dist), _)| {
                                    action != NavAction::Wait
                                        && (odo + dist - s.at).abs() <= tol(dist)
                                });
                            let seen = agrees.and_then(|(_, bbox)| truth(&bbox));
                            out.reads.push(ConfirmationRead {
                                t,
                                sighting: s.action,
                                read: agrees.map(|((action, _), _)| action),
                                read_m: agrees.map(|((_, dist), _)| dist),
                                truth: seen.and_then(|(class, _)| meaning(actions, class)),
                                true_m: seen.map(|(_, depth)| depth),
                            });
                            if let Some(((action, dist), _)) = agrees {
                                let (before, was) = (s.action, s.verified);
                                let true_dist = seen.map(|(_, depth)| depth);
                                s.confirmed(action, odo, dist, true_dist);
                                if !was || s.action != before {
                                    out.events.push(format!(
                                        "{before:?} sign {dist:.2} m ahead{} confirmed as {:?}",
                                        truly(true_dist),
                                        s.action
                                    ));
                                }
                            } else if s.verified {
                                // confirmed before: this reading abstains, unless such
                                // readings now outnumber the votes of its action
                                s.blanks += 1.0;
                                s.confirmed_at = odo;
                                let best = s.votes.iter().copied().fold(0.0, f64::max);
                                if s.blanks > best {
                                    let (action, at) = (s.action, s.at);
                                    out.events.push(format!(
                                        "{action:?} sign {:.2} m ahead no longer confirmed ({} readings of nothing there)",
                                        at - odo,
                                        s.blanks
                                    ));
                                    self.sightings.remove(i);
                                }
                            } else {
                                self.rejections += 1;
                                let at = s.at;
                                out.events.push(format!(
                                    "{:?} sign {:.2} m ahead not confirmed",
                                    self.sightings[i].action,
                                    at - odo
                                ));
                                self.sightings.remove(i);
                            }
                        }
                    }
                }
                // signs already passed, or not read for a while, are forgotten
                self.sightings
                    .retain(|s| s.at > odo - 0.5 && (s.peak >= need_f || s.support > 0.05));
                // carry out the best-supported manoeuvre once the odometer reaches it
                let sightings = &self.sightings;
                let due = sightings
                    .iter()
                    .filter(|s| {
                        let trigger = trigger_of(s);
                        s.peak >= need_f && s.verified && s.stands_still() && odo >= s.at - trigger
                    })
                    .filter(|s| {
                        // contradicted at the same spot (within the matching tolerance of
                        // the farther reading) by another confirmed action last read
                        // closer (a sign read close up, its arrow a larger box, is the
                        // better reading; equally close: the better supported): not
                        // this one
                        !sightings.iter().any(|o| {
                            let tol = spot_tolerance(o.dist.max(s.dist)).max(1.0);
                            o.action != s.action
                                && (o.at - s.at).abs() <= tol
                                && o.peak >= need_f
                                && o.verified
                                && (o.dist < s.dist || (o.dist == s.dist && o.peak >= s.peak))
                        })
                    })
                    .filter(|s| {
                        // superseded by a sighting just beyond it that was read after
                        // its last reading: the same sign, read short from afar (its
                        // box too large) and then read right as the drone came closer
                        !sightings.iter().any(|o| {
                            let gap = o.at - s.at;
                            gap > 0.0
                                && gap <= 2.0 * spot_tolerance(s.dist)
                                && o.fit.x_max > s.fit.x_max
                                && o.peak >= need_f
                                && o.verified
                                && o.stands_still()
                        })
                    })
                    .max_by(|a, b| a.peak.total_cmp(&b.peak))
                    .copied();
                for s in &mut self.sightings {
                    if !std::mem::take(&mut s.held) {
                        s.support *= SUPPORT_DECAY;
                    }
                }
                match due {
                    Some(Sighting {
                        action: NavAction::Stop,
                        dist,
                        true_dist,
                        ..
                    }) if self.mode == Mode::Cruise => {
                        self.sightings.clear();
                        landed = true;
                        out.events.push(format!(
                            "land at STOP (last read at {dist:.2} m{})",
                            truly(true_dist)
                        ));
                    }
                    Some(Sighting {
                        action: action @ (NavAction::TurnLeft | NavAction::TurnRight),
                        dist,
                        true_dist,
                        fit,
                        ..
                    }) if self.mode == Mode::Cruise => {
                        self.sightings.clear();
                        let left = action == NavAction::TurnLeft;
                        turned = Some(left);
                        self.mode = Mode::Turning;
                        out.events.push(format!(
                            "turn {} (last read at {dist:.2} m{}; {} readings over {:.2} m, approach {:.2})",
                            if left { "left" } else { "right" },
                            truly(true_dist),
                            fit.n,
                            fit.span(),
                            fit.approach().unwrap_or(f64::NAN)
                        ));
                    }
                    _ => {}
                }
                if self.mode == Mode::Cruise && odo < self.wait_zone_until && input.pedestrian_close
                {
                    self.mode = Mode::HoldForPedestrian;
                }
            }
            Mode::Done => {}
        }
        if landed {
            self.mode = Mode::Done;
        }
        let holding = |m: Mode| matches!(m, Mode::Waiting | Mode::HoldForPedestrian);
        out.command = match (turned, landed) {
            (Some(true), _) => Some(NavCommand::TurnLeft),
            (Some(false), _) => Some(NavCommand::TurnRight),
            (None, true) => Some(NavCommand::Land),
            (None, false) if holding(self.mode) && !holding(prev_mode) => Some(NavCommand::Hold),
            (None, false) if holding(prev_mode) && self.mode == Mode::Cruise => {
                Some(NavCommand::Resume)
            }
            _ => None,
        };
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames of one large, centred detection of class 0 until a command comes.
    fn first_command(navigator: &mut Navigator) -> Option<NavCommand> {
        let det = Detection {
            bbox: BBox::new(190.0, 40.0, 290.0, 240.0),
            score: 0.9,
            class: 0,
        };
        for k in 0..30 {
            let input = NavInput {
                t: f64::from(k) * 0.1,
                odometer: 0.0,
                turn_done: false,
                pedestrian_close: false,
                detections: &[det],
                tracked: false,
            };
            let step = navigator
                .step(&input, || Ok::<_, ()>(Some(vec![det])), &|_| None)
                .expect("step");
            if step.command.is_some() {
                return step.command;
            }
        }
        None
    }

    #[test]
    fn a_class_means_what_the_action_table_says() {
        let optics = Optics {
            width: 480,
            focal_px: 340.0,
            sign_size: 0.3,
        };
        let nav = NavConfig::default();
        let make = || Navigator::new(&nav, 2.0, optics);
        assert_eq!(make().action_of(0), Sign::from_id(0).and_then(Sign::action));
        let mut wait = make().with_actions(vec![Some(NavAction::Wait)]);
        assert_eq!(first_command(&mut wait), Some(NavCommand::Hold));
        let mut nothing = make().with_actions(vec![None]);
        assert_eq!(nothing.action_of(0), None);
        assert_eq!(first_command(&mut nothing), None);
        assert_eq!(nothing.action_of(7), None, "past the table: nothing");
    }
}
