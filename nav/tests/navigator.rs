//! The navigator's rules, stepped frame by frame: a WAIT sign holds the drone only when
//! read on `confirm_frames` frames in a row and the drone resumes after `wait_min_s`;
//! a turn sign is obeyed only when the reference variant's re-reading confirms it, and
//! never from tracked boxes alone.
use frugal_data::Sign;
use frugal_nav::{Mode, NavCommand, NavConfig, NavInput, Navigator, Optics};
use frugal_runtime::{BBox, Detection};

const OPTICS: Optics = Optics {
    width: 480,
    focal_px: 342.8,
    sign_size: 0.45,
};

fn sign(sign: Sign, dist: f64) -> Detection {
    let h = (OPTICS.focal_px * OPTICS.sign_size / dist) as f32;
    Detection {
        bbox: BBox {
            x1: 240.0 - h / 2.0,
            y1: 135.0 - h / 2.0,
            x2: 240.0 + h / 2.0,
            y2: 135.0 + h / 2.0,
        },
        score: 0.9,
        class: sign.id(),
    }
}

/// Step `nav` on one frame; `confirm` is what the reference variant reads.
fn step(
    nav: &mut Navigator,
    t: f64,
    odometer: f64,
    detections: &[Detection],
    tracked: bool,
    confirm: &[Detection],
) -> Option<NavCommand> {
    let input = NavInput {
        t,
        odometer,
        turn_done: false,
        pedestrian_close: false,
        detections,
        tracked,
    };
    nav.step(
        &input,
        || Ok::<_, std::convert::Infallible>(Some(confirm.to_vec())),
        &|_| None,
    )
    .unwrap()
    .command
}

#[test]
fn a_wait_sign_holds_only_after_confirm_frames_in_a_row_then_resumes() {
    let config = NavConfig::default();
    assert_eq!(config.confirm_frames, 3);
    let mut nav = Navigator::new(&config, 3.0, OPTICS);
    let wait = [sign(Sign::Wait, 2.0)];
    let mut commands = Vec::new();
    // read twice, missed once, read twice: never three in a row
    for (i, seen) in [true, true, false, true, true].into_iter().enumerate() {
        let d: &[Detection] = if seen { &wait } else { &[] };
        commands.push(step(&mut nav, i as f64 * 0.1, 0.0, d, false, d));
    }
    assert_eq!(commands, [None; 5]);
    assert_eq!(nav.mode(), Mode::Cruise);
    // the third in a row holds
    assert_eq!(
        step(&mut nav, 0.5, 0.0, &wait, false, &wait),
        Some(NavCommand::Hold)
    );
    assert_eq!(nav.mode(), Mode::Waiting);
    // not before wait_min_s, then resume
    assert_eq!(step(&mut nav, 0.5 + 0.9, 0.0, &[], false, &[]), None);
    assert_eq!(
        step(&mut nav, 0.5 + config.wait_min_s, 0.0, &[], false, &[]),
        Some(NavCommand::Resume)
    );
    assert_eq!(nav.mode(), Mode::Cruise);
}

/// Fly 3 m towards a TURN LEFT sign 4 m ahead, reading it on every frame; the
/// reference variant reads it too when `confirmed`, nothing otherwise. The commands
/// issued.
fn approach(tracked: bool, confirmed: bool) -> Vec<NavCommand> {
    let mut nav = Navigator::new(&NavConfig::default(), 3.0, OPTICS);
    let mut out = Vec::new();
    for i in 0..100 {
        let odo = f64::from(i) * 0.03;
        let seen = [sign(Sign::TurnLeft, 4.0 - odo)];
        let confirm = if confirmed { &seen[..] } else { &[][..] };
        out.extend(step(
            &mut nav,
            f64::from(i) * 0.1,
            odo,
            &seen,
            tracked,
            confirm,
        ));
        if nav.mode() == Mode::Turning {
            break;
        }
    }
    out
}

#[test]
fn a_turn_sign_is_obeyed_only_when_confirmed_and_measured() {
    // read on every frame and confirmed: a left turn at the junction
    assert_eq!(approach(false, true), [NavCommand::TurnLeft]);
    // the reference variant sees nothing there: no turn
    assert_eq!(approach(false, false), []);
    // boxes a tracker carried place no sign
    assert_eq!(approach(true, true), []);
}
