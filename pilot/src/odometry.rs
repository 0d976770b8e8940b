//! The autopilot's own estimate of where the drone is, read from MAVLink
//! (`--mavlink-odometry`): `LOCAL_POSITION_NED` gives the distance flown and
//! `ATTITUDE` the heading, in place of dead reckoning.
//!
//! - **Distance flown** is the length of the horizontal path. Position estimates
//!   jitter by centimetres at tens of hertz, and summing every small step would count
//!   that jitter as flight; so the path advances only once the drone is
//!   [`DEADBAND_M`] away from where it was last counted.
//! - **Heading** is the autopilot's yaw relative to the first one received, so the
//!   navigator's corridor grid starts along the drone's first heading. MAVLink's yaw
//!   grows clockwise seen from above (NED), as the navigator's does.

/// Movement smaller than this from the last counted position is not counted, metres.
pub const DEADBAND_M: f64 = 0.1;

/// The pose the autopilot reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MavOdometry {
    odometer_m: f64,
    anchor: Option<(f64, f64)>,
    yaw0: Option<f64>,
    yaw: Option<f64>,
    /// `LOCAL_POSITION_NED` messages read.
    pub positions: u64,
    /// `ATTITUDE` messages read.
    pub attitudes: u64,
}

impl MavOdometry {
    /// A `LOCAL_POSITION_NED` (north, east, metres); non-finite values are ignored.
    pub fn position(&mut self, north: f64, east: f64) {
        if !(north.is_finite() && east.is_finite()) {
            return;
        }
        self.positions += 1;
        match self.anchor {
            None => self.anchor = Some((north, east)),
            Some((n, e)) => {
                let step = (north - n).hypot(east - e);
                if step >= DEADBAND_M {
                    self.odometer_m += step;
                    self.anchor = Some((north, east));
                }
            }
        }
    }

    /// An `ATTITUDE` yaw (radians, clockwise from north); non-finite values are ignored.
    pub fn attitude(&mut self, yaw: f64) {
        if !yaw.is_finite() {
            return;
        }
        self.attitudes += 1;
        let y0 = *self.yaw0.get_or_insert(yaw);
        self.yaw = Some(frugal_nav::heading::wrap(yaw - y0));
    }

    /// Distance flown (metres) and heading relative to the first (radians, in
    /// `(-π, π]`), once both a position and an attitude have arrived.
    pub fn pose(&self) -> Option<(f64, f64)> {
        self.anchor?;
        Some((self.odometer_m, self.yaw?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn jitter_is_not_flight_and_a_straight_leg_is_its_length() {
        let mut o = MavOdometry::default();
        o.attitude(0.3);
        assert_eq!(o.pose(), None, "no position yet");
        // hovering with 2 cm of jitter for 10 s at 50 Hz
        for i in 0..500 {
            let j = if i % 2 == 0 { 0.02 } else { -0.02 };
            o.position(10.0 + j, -4.0 - j);
        }
        assert_eq!(o.pose(), Some((0.0, 0.0)));
        // 3 m east in 1 cm steps, the same jitter on top
        for i in 0..=300 {
            let j = if i % 2 == 0 { 0.02 } else { -0.02 };
            o.position(10.0 + j, -4.0 + i as f64 * 0.01);
        }
        let (odo, _) = o.pose().unwrap();
        assert!((odo - 3.0).abs() < 0.1, "{odo}");
        o.position(f64::NAN, 0.0);
        assert_eq!(o.positions, 801);
    }

    #[test]
    fn heading_is_relative_to_the_first_and_wraps() {
        let mut o = MavOdometry::default();
        o.position(0.0, 0.0);
        o.attitude(PI - 0.1);
        assert_eq!(o.pose().unwrap().1, 0.0);
        // a quarter turn clockwise across ±π
        o.attitude(-PI + 0.1 + FRAC_PI_2 - 0.2);
        assert!((o.pose().unwrap().1 - FRAC_PI_2).abs() < 1e-12);
        o.attitude(f64::INFINITY);
        assert_eq!(o.attitudes, 2);
    }
}
