//! Headings: wrapping an angle, the heading a 90° turn aims at, and when a turn is
//! over.
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// A turn is over when the heading is this close to its target, radians.
pub const TURN_TOLERANCE: f64 = 1e-6;

/// `a` wrapped into `(-π, π]`.
pub fn wrap(a: f64) -> f64 {
    let a = a.rem_euclid(TAU);
    if a > PI { a - TAU } else { a }
}

/// The heading a quarter turn from `yaw` aims at (left: `yaw − π/2`, right:
/// `yaw + π/2`, the simulator's yaw growing clockwise seen from above), snapped to the
/// nearest multiple of π/2 so that turns do not accumulate error along a corridor grid.
pub fn turn_target(yaw: f64, left: bool) -> f64 {
    let target = wrap(yaw + if left { -FRAC_PI_2 } else { FRAC_PI_2 });
    wrap((target / FRAC_PI_2).round() * FRAC_PI_2)
}

/// Whether `yaw` has reached `target` ([`TURN_TOLERANCE`]).
pub fn reached(target: f64, yaw: f64) -> bool {
    wrap(target - yaw).abs() < TURN_TOLERANCE
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_turns_snap_to_the_grid_and_wrap() {
        assert_eq!(turn_target(0.0, false), FRAC_PI_2);
        assert_eq!(turn_target(0.0, true), -FRAC_PI_2);
        assert!((turn_target(PI, false) + FRAC_PI_2).abs() < 1e-12);
        assert_eq!(turn_target(0.01, false), FRAC_PI_2);
        assert!(reached(PI, -PI));
        assert!(!reached(FRAC_PI_2, 0.0));
    }
}
