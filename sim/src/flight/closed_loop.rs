//! The loop itself: [`fly`] renders a frame, hands it to the perception, flies the
//! interval the perception took on the current command, then decides on the frame's
//! detections (see the [module documentation](super) for the timing model).
use super::config::FlightConfig;
use super::geometry::{collides, rnd, start_pose, wrap};
use super::ground_truth::{score, true_sign};
use super::result::{Event, FlightError, FlightResult, FrameView, Mode, Outcome, TrackPoint};
use crate::maze::Maze;
use crate::perception::{FrameInput, Perception};
use crate::render::{Renderer, Walker};
use frugal_nav::heading::{reached, turn_target};
use frugal_nav::{NavCommand, NavInput, Navigator, Optics};
use frugal_runtime::{Detection, FrameRef};
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
    config.device.check().map_err(FlightError::Config)?;
    if cam.width < 16 || cam.height < 16 || !(1.0..179.0).contains(&cam.hfov_deg) {
        return Err(FlightError::Config(format!(
            "camera {}×{} with {}° field of view",
            cam.width, cam.height, cam.hfov_deg
        )));
    }
    let yaw_rate = nav.yaw_rate_deg.to_radians();
    let name = perception.name();

    let mut renderer = Renderer::new(maze, cam, seed);
    let offsets: Vec<f64> = (0..maze.zones.len())
        .map(|i| rnd(seed, 100 + i as i64) * maze.zones[i].period)
        .collect();
    let mut pose = start_pose(maze, seed);
    let mut target_yaw = pose.yaw;
    let mut navigator = Navigator::new(
        nav,
        maze.cell,
        Optics {
            width: cam.width,
            focal_px: cam.focal_px(),
            sign_size: maze.sign_size,
        },
    );
    let mut mode = navigator.mode();
    let mut speed = 0.0; // hover until the first frame is processed
    let mut t = 0.0;
    let mut dt_avg: Option<f64> = None;
    let mut odo = 0.0;
    let mut wait_s = 0.0;
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
    let (mut int8_total, mut tracker_total) = (0.0, 0.0);
    let (mut sign_frames, mut sign_hits, mut false_detections) = (0u64, 0u64, 0u64);
    let mut confirmation_reads = Vec::new();
    // device time of confirmations, charged to the next interval, s
    let mut pending_s = 0.0;
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
        int8_total += percept.int8_ms;
        tracker_total += percept.tracker_ms;
        score(
            &truth,
            &percept.detections,
            &mut sign_frames,
            &mut sign_hits,
            &mut false_detections,
        );
        let dt = config.device.device_ms(&percept) / 1e3 + std::mem::take(&mut pending_s);
        let dt = dt.max(min_dt);
        // the camera frames perception drops before the next one it takes
        let dt = dt + perception.camera_wait_s(t + dt, min_dt);
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
        let decided_yaw = pose.yaw;
        let turn_done = mode == Mode::Turning && reached(target_yaw, pose.yaw);
        if turn_done {
            pose.yaw = target_yaw;
        }
        let input_nav = NavInput {
            t,
            odometer: odo,
            turn_done,
            pedestrian_close: ped_close,
            detections: &percept.detections,
            tracked: percept.tracked,
        };
        // what the reference detector read, if the navigator asked (for the observer)
        let mut confirm_read: Option<Option<Vec<Detection>>> = None;
        let step = navigator.step(
            &input_nav,
            || match perception.confirm(&input) {
                Ok(Some(check)) => {
                    pending_s += config.device.device_ms(&check) / 1e3;
                    compute_total += check.compute_ms.max(0.0);
                    int8_total += check.int8_ms.max(0.0);
                    tracker_total += check.tracker_ms.max(0.0);
                    confirm_read = Some(Some(check.detections.clone()));
                    Ok(Some(check.detections))
                }
                Ok(None) => {
                    confirm_read = Some(None);
                    Ok(None)
                }
                Err(source) => Err(FlightError::Perception {
                    name: name.clone(),
                    frame: frames - 1,
                    source,
                }),
            },
            &|bbox| true_sign(&truth, bbox).map(|g| (g.class, g.depth)),
        )?;
        confirmation_reads.extend(step.reads);
        events.extend(step.events.into_iter().map(|what| Event {
            t,
            x: pose.x,
            y: pose.y,
            what,
        }));
        let landed = step.command == Some(NavCommand::Land);
        if let Some(c @ (NavCommand::TurnLeft | NavCommand::TurnRight)) = step.command {
            target_yaw = turn_target(pose.yaw, c == NavCommand::TurnLeft);
        }
        mode = navigator.mode();
        speed = match mode {
            Mode::Cruise => nav.cruise_speed(dt_avg.unwrap_or(dt)),
            _ => 0.0,
        };
        if let Some(obs) = observer.as_mut() {
            obs(&FrameView {
                index: frames - 1,
                time_s: t - dt,
                pose,
                image,
                truth: &truth,
                detections: &percept.detections,
                tracked: percept.tracked,
                confirm: confirm_read.as_ref().map(Option::as_deref),
                mode,
                decision_s: t,
                odometer: odo,
                yaw: decided_yaw,
                pedestrian_close: ped_close,
                command: step.command,
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
        int8_ms_mean: int8_total / n,
        tracker_ms_mean: tracker_total / n,
        render_ms_mean: render_total / n,
        wait_s,
        sign_frames,
        sign_hits,
        false_detections,
        confirmations: navigator.confirmations(),
        rejections: navigator.rejections(),
        confirmation_reads,
        perception_counts: perception.counts(),
        track,
        events,
    })
}
