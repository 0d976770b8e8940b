//! The loop itself: [`fly`] renders a frame, hands it to the perception, flies the
//! interval the perception took on the current command, then decides on the frame's
//! detections (see the [module documentation](super) for the timing model).
use super::config::FlightConfig;
use super::geometry::{collides, rnd, start_pose, wrap};
use super::ground_truth::{score, true_sign, truly};
use super::result::{
    ConfirmationRead, Event, FlightError, FlightResult, FrameView, Mode, Outcome, TrackPoint,
};
use super::sighting::{
    RECONFIRM_EVERY, SUPPORT_DECAY, Sighting, outranked_dropped, spot_tolerance,
};
use crate::maze::Maze;
use crate::perception::{FrameInput, Perception};
use crate::render::{Renderer, Walker};
use frugal_data::{NavAction, Sign};
use frugal_runtime::{Detection, FrameRef};
use std::f64::consts::FRAC_PI_2;
use std::time::Instant;

/// Fly `maze` once with `perception` and `seed`. `observer` sees every processed frame
/// (to save images); pass `None` when not needed.
pub fn fly(
    maze: &Maze,
    config: &FlightConfig,
    perception: &mut dyn Perception,
    seed: u64,
    mut observer: Option<&mut dyn FnMut(&FrameView<'_>)>,
) -> Result<FlightResult, FlightError> {
    let nav = &config.nav;
    let cam = config.camera;
    if !(nav.v_max > 0.0
        && nav.react_distance > 0.0
        && nav.time_limit_s > 0.0
        && nav.camera_fps > 0.0)
    {
        return Err(FlightError::Config(
            "v_max, react_distance, time_limit_s and camera_fps must be positive".into(),
        ));
    }
    if !(config.device.slowdown > 0.0 && config.device.slowdown.is_finite()) {
        return Err(FlightError::Config(format!(
            "device slowdown must be positive, got {}",
            config.device.slowdown
        )));
    }
    if cam.width < 16 || cam.height < 16 || !(1.0..179.0).contains(&cam.hfov_deg) {
        return Err(FlightError::Config(format!(
            "camera {}×{} with {}° field of view",
            cam.width, cam.height, cam.hfov_deg
        )));
    }
    let half_cell = maze.cell / 2.0;
    let turn_distance = nav.turn_distance.unwrap_or(half_cell);
    let land_distance = nav.land_distance.unwrap_or(half_cell);
    let commit_distance = nav
        .commit_distance
        .unwrap_or(2.0 * maze.cell)
        .max(turn_distance)
        .max(land_distance);
    let zone_length = nav.wait_zone_length.unwrap_or(3.0 * maze.cell);
    let rearm = nav.rearm_distance.unwrap_or(half_cell);
    let yaw_rate = nav.yaw_rate_deg.to_radians();
    let name = perception.name();

    let mut renderer = Renderer::new(maze, cam, seed);
    let offsets: Vec<f64> = (0..maze.zones.len())
        .map(|i| rnd(seed, 100 + i as i64) * maze.zones[i].period)
        .collect();
    let mut pose = start_pose(maze, seed);
    let mut target_yaw = pose.yaw;
    let mut mode = Mode::Cruise;
    let mut speed = 0.0; // hover until the first frame is processed
    let mut t = 0.0;
    let mut dt_avg: Option<f64> = None;
    let mut odo = 0.0;
    let mut turn_armed_at = 0.0;
    let mut wait_zone_until = f64::NEG_INFINITY;
    let mut wait_started = 0.0;
    let mut wait_s = 0.0;
    let mut streak: Option<(NavAction, u32)> = None;
    // turn and STOP signs read ahead, placed on the odometer
    let mut sightings: Vec<Sighting> = Vec::new();
    let mut rgb = Vec::new();
    let mut track = vec![TrackPoint {
        t,
        x: pose.x,
        y: pose.y,
        yaw: pose.yaw,
        mode,
    }];
    let mut events = Vec::new();
    let mut frames = 0u64;
    let (mut compute_total, mut render_total) = (0.0, 0.0);
    let (mut sign_frames, mut sign_hits, mut false_detections) = (0u64, 0u64, 0u64);
    let (mut confirmations, mut rejections) = (0u64, 0u64);
    let mut confirmation_reads = Vec::new();
    // compute time of confirmations, charged to the next interval
    let mut pending_ms = 0.0;
    let f_px = cam.focal_px();
    let min_dt = 1.0 / nav.camera_fps;
    let outcome;

    loop {
        // Capture.
        let walkers: Vec<Walker> = maze
            .zones
            .iter()
            .enumerate()
            .filter_map(|(i, z)| {
                z.pedestrian_at(t, offsets[i], maze.cell).map(|pos| Walker {
                    zone: i,
                    pos,
                    phase: (t + offsets[i]) * 5.0,
                })
            })
            .collect();
        let started = Instant::now();
        let truth = renderer.render(pose, &walkers, frames, &mut rgb);
        render_total += started.elapsed().as_secs_f64() * 1e3;
        let image = FrameRef {
            width: cam.width,
            height: cam.height,
            rgb: &rgb,
        };
        let input = FrameInput {
            image,
            time_s: t,
            index: frames,
            truth: &truth,
        };
        let percept = perception
            .perceive(&input)
            .map_err(|source| FlightError::Perception {
                name: name.clone(),
                frame: frames,
                source,
            })?;
        compute_total += percept.compute_ms;
        score(
            &truth,
            &percept.detections,
            &mut sign_frames,
            &mut sign_hits,
            &mut false_detections,
        );
        let compute_ms = percept.compute_ms.max(0.0) + std::mem::take(&mut pending_ms);
        let dt = (compute_ms / 1e3 * config.device.slowdown).max(min_dt);
        dt_avg = Some(dt_avg.map_or(dt, |a| a * 0.7 + dt * 0.3));

        // Fly the interval on the current command.
        let mut crashed = None;
        let mut remaining = dt.min(nav.time_limit_s - t + 1e-9);
        while remaining > 0.0 {
            let step = if speed > 0.0 {
                remaining.min(0.02 / speed)
            } else {
                remaining
            };
            if mode == Mode::Turning {
                let diff = wrap(target_yaw - pose.yaw);
                let turn = (yaw_rate * step).min(diff.abs());
                pose.yaw = wrap(pose.yaw + turn * diff.signum());
            } else if speed > 0.0 {
                let (nx, ny) = (
                    pose.x + pose.yaw.cos() * speed * step,
                    pose.y + pose.yaw.sin() * speed * step,
                );
                odo += speed * step;
                pose.x = nx;
                pose.y = ny;
                if collides(maze, nx, ny, nav.radius) {
                    crashed = Some((nx, ny));
                    t += step;
                    break;
                }
            }
            if matches!(mode, Mode::Waiting | Mode::HoldForPedestrian) {
                wait_s += step;
            }
            t += step;
            remaining -= step;
        }
        frames += 1;
        if let Some((x, y)) = crashed {
            events.push(Event {
                t,
                x,
                y,
                what: "collision".into(),
            });
            outcome = Outcome::Collision { x, y };
            break;
        }
        if t >= nav.time_limit_s {
            outcome = Outcome::TimeLimit {
                limit_s: nav.time_limit_s,
            };
            break;
        }

        // Decide on this frame's detections.
        let prev_mode = mode;
        let ped_close = truth
            .pedestrians
            .iter()
            .any(|p| p.depth <= nav.pedestrian_distance);
        let mut landed = false;
        match mode {
            Mode::Turning => {
                if wrap(target_yaw - pose.yaw).abs() < 1e-6 {
                    pose.yaw = target_yaw;
                    mode = Mode::Cruise;
                    turn_armed_at = odo + rearm;
                }
            }
            Mode::Waiting => {
                if t - wait_started >= nav.wait_min_s && !ped_close {
                    mode = Mode::Cruise;
                    wait_zone_until = odo + zone_length;
                    events.push(Event {
                        t,
                        x: pose.x,
                        y: pose.y,
                        what: "resume: WAIT zone clear".into(),
                    });
                }
            }
            Mode::Cruise | Mode::HoldForPedestrian => {
                mode = Mode::Cruise;
                // what a detection would make the drone do, and how far away the sign is
                let reading = |d: &Detection| {
                    let action = Sign::from_id(d.class)?.action()?;
                    let dist = f_px * maze.sign_size / f64::from(d.bbox.height()).max(1e-3);
                    let (cx, _) = d.bbox.center();
                    let centred = (f64::from(cx) - f64::from(cam.width) / 2.0).abs()
                        <= nav.centre_band * f64::from(cam.width);
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
                let candidate = outranked_dropped(&percept.detections)
                    .find_map(|d| reading(d).map(|(action, dist)| (action, dist, d.bbox)));
                let need = nav.confirm_frames.max(1);
                match candidate {
                    Some((NavAction::Wait, dist, _)) => {
                        // … a WAIT sign after `need` frames in a row …
                        streak = match streak {
                            Some((NavAction::Wait, n)) => Some((NavAction::Wait, n + 1)),
                            _ => Some((NavAction::Wait, 1)),
                        };
                        if streak.is_some_and(|(_, n)| n >= need) {
                            mode = Mode::Waiting;
                            wait_started = t;
                            streak = None;
                            events.push(Event {
                                t,
                                x: pose.x,
                                y: pose.y,
                                what: format!("stop at WAIT (estimated {dist:.2} m)"),
                            });
                        }
                    }
                    // … a turn or STOP sign is placed on the odometer, where readings
                    // of it accumulate
                    Some((action, dist, bbox)) => {
                        streak = None;
                        let at = odo + dist;
                        let tol = spot_tolerance(dist);
                        let true_dist = || true_sign(&truth, &bbox).map(|g| g.depth);
                        match sightings
                            .iter_mut()
                            .find(|s| (s.action == action || s.settled) && (s.at - at).abs() <= tol)
                        {
                            // a carried box holds a sighting's support but adds none,
                            // and neither places nor starts a sighting: it repeats the
                            // last detection (a weak false one would build support
                            // frame after frame) and its size is the tracker's
                            // prediction (a box stuck at one size close up would push
                            // the manoeuvre ahead of the drone)
                            Some(s) if percept.tracked => s.hold(),
                            Some(s) => s.read(odo, dist, true_dist()),
                            None if percept.tracked => {}
                            None => sightings.push(Sighting::new(action, odo, dist, true_dist())),
                        }
                    }
                    None => streak = None,
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
                if let Some(i) = sightings.iter().position(|s| {
                    s.peak >= need_f
                        && (!s.verified
                            || (s.settled
                                && odo - s.confirmed_at >= RECONFIRM_EVERY
                                && odo < s.at - trigger_of(s)))
                }) {
                    let check =
                        perception
                            .confirm(&input)
                            .map_err(|source| FlightError::Perception {
                                name: name.clone(),
                                frame: frames - 1,
                                source,
                            })?;
                    match check {
                        None => sightings
                            .iter_mut()
                            .filter(|s| s.peak >= need_f)
                            .for_each(|s| s.verified = true),
                        Some(check) => {
                            confirmations += 1;
                            pending_ms += check.compute_ms.max(0.0);
                            compute_total += check.compute_ms.max(0.0);
                            let s = &mut sightings[i];
                            let tol = |dist: f64| spot_tolerance(dist.max(s.dist));
                            let agrees = outranked_dropped(&check.detections)
                                .filter_map(|d| reading(d).map(|r| (r, d.bbox)))
                                .find(|&((action, dist), _)| {
                                    action != NavAction::Wait
                                        && (odo + dist - s.at).abs() <= tol(dist)
                                });
                            let seen = agrees.and_then(|(_, bbox)| true_sign(&truth, &bbox));
                            confirmation_reads.push(ConfirmationRead {
                                t,
                                sighting: s.action,
                                read: agrees.map(|((action, _), _)| action),
                                read_m: agrees.map(|((_, dist), _)| dist),
                                truth: seen.and_then(|g| Sign::from_id(g.class)?.action()),
                                true_m: seen.map(|g| g.depth),
                            });
                            if let Some(((action, dist), _)) = agrees {
                                let (before, was) = (s.action, s.verified);
                                let true_dist = seen.map(|g| g.depth);
                                s.confirmed(action, odo, dist, true_dist);
                                if !was || s.action != before {
                                    events.push(Event {
                                        t,
                                        x: pose.x,
                                        y: pose.y,
                                        what: format!(
                                            "{before:?} sign {dist:.2} m ahead{} confirmed as {:?}",
                                            truly(true_dist),
                                            s.action
                                        ),
                                    });
                                }
                            } else if s.verified {
                                // confirmed before: this reading abstains, unless such
                                // readings now outnumber the votes of its action
                                s.blanks += 1.0;
                                s.confirmed_at = odo;
                                let best = s.votes.iter().copied().fold(0.0, f64::max);
                                if s.blanks > best {
                                    let (action, at) = (s.action, s.at);
                                    events.push(Event {
                                        t,
                                        x: pose.x,
                                        y: pose.y,
                                        what: format!(
                                            "{action:?} sign {:.2} m ahead no longer confirmed ({} readings of nothing there)",
                                            at - odo,
                                            s.blanks
                                        ),
                                    });
                                    sightings.remove(i);
                                }
                            } else {
                                rejections += 1;
                                let at = s.at;
                                events.push(Event {
                                    t,
                                    x: pose.x,
                                    y: pose.y,
                                    what: format!(
                                        "{:?} sign {:.2} m ahead not confirmed",
                                        sightings[i].action,
                                        at - odo
                                    ),
                                });
                                sightings.remove(i);
                            }
                        }
                    }
                }
                // signs already passed, or not read for a while, are forgotten
                sightings.retain(|s| s.at > odo - 0.5 && (s.peak >= need_f || s.support > 0.05));
                // carry out the best-supported manoeuvre once the odometer reaches it
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
                for s in &mut sightings {
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
                    }) if mode == Mode::Cruise => {
                        sightings.clear();
                        landed = true;
                        events.push(Event {
                            t,
                            x: pose.x,
                            y: pose.y,
                            what: format!(
                                "land at STOP (last read at {dist:.2} m{})",
                                truly(true_dist)
                            ),
                        });
                    }
                    Some(Sighting {
                        action: action @ (NavAction::TurnLeft | NavAction::TurnRight),
                        dist,
                        true_dist,
                        fit,
                        ..
                    }) if mode == Mode::Cruise => {
                        sightings.clear();
                        let left = action == NavAction::TurnLeft;
                        target_yaw = wrap(pose.yaw + if left { -FRAC_PI_2 } else { FRAC_PI_2 });
                        // Snap to the grid axes so turns do not accumulate error.
                        target_yaw = wrap((target_yaw / FRAC_PI_2).round() * FRAC_PI_2);
                        mode = Mode::Turning;
                        events.push(Event {
                            t,
                            x: pose.x,
                            y: pose.y,
                            what: format!(
                                "turn {} (last read at {dist:.2} m{}; {} readings over {:.2} m, approach {:.2})",
                                if left { "left" } else { "right" },
                                truly(true_dist),
                                fit.n,
                                fit.span(),
                                fit.approach().unwrap_or(f64::NAN)
                            ),
                        });
                    }
                    _ => {}
                }
                if mode == Mode::Cruise && odo < wait_zone_until && ped_close {
                    mode = Mode::HoldForPedestrian;
                }
            }
            Mode::Done => {}
        }
        speed = match mode {
            Mode::Cruise => nav.v_max.min(nav.react_distance / dt_avg.unwrap_or(dt)),
            _ => 0.0,
        };
        if landed {
            mode = Mode::Done;
        }
        if let Some(obs) = observer.as_mut() {
            obs(&FrameView {
                index: frames - 1,
                time_s: t - dt,
                pose,
                image,
                truth: &truth,
                detections: &percept.detections,
                mode,
            });
        }
        let last_t = track.last().map_or(0.0, |p| p.t);
        if mode != prev_mode || t - last_t >= 0.25 {
            track.push(TrackPoint {
                t,
                x: pose.x,
                y: pose.y,
                yaw: pose.yaw,
                mode,
            });
        }
        if landed {
            let cell = maze
                .cell_of(pose.x, pose.y)
                .unwrap_or((usize::MAX, usize::MAX));
            outcome = if cell == maze.goal {
                Outcome::Success
            } else {
                Outcome::LandedOutsideGoal { cell }
            };
            break;
        }
    }
    track.push(TrackPoint {
        t,
        x: pose.x,
        y: pose.y,
        yaw: pose.yaw,
        mode: Mode::Done,
    });
    let n = frames.max(1) as f64;
    Ok(FlightResult {
        maze: maze.name.clone(),
        seed,
        perception: name,
        device: config.device.clone(),
        outcome,
        time_s: t,
        frames,
        fps: if t > 0.0 { frames as f64 / t } else { 0.0 },
        path_m: odo,
        avg_velocity: if t > 0.0 { odo / t } else { 0.0 },
        compute_ms_mean: compute_total / n,
        render_ms_mean: render_total / n,
        wait_s,
        sign_frames,
        sign_hits,
        false_detections,
        confirmations,
        rejections,
        confirmation_reads,
        perception_counts: perception.counts(),
        track,
        events,
    })
}
