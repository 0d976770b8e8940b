//! Forecasting the boxes shown to the time they are used (after Li, Wang, Ramanan,
//! "Towards Streaming Perception", ECCV 2020).
//!
//! Perception's output for frame `t` is ready after frame `t` has gone: on the drone,
//! and in streaming AP, it is used on a later frame, when the sign has moved. A
//! [`Forecaster`] keeps, per box of the latest output, a velocity in pixels per frame
//! and moves the boxes to the frame they are used on:
//!
//! - [`Forecaster::update`] takes each output in processing order (its frame index and
//!   the boxes it shows). A new box is matched to a box of the previous output of the
//!   same class: the one with the highest IoU, either as it was or moved on at its own
//!   velocity, if that IoU is at least [`ForecastParams::min_iou`]. Its velocity is then
//!   the centre's displacement per frame since that box, smoothed with the matched
//!   box's velocity by [`ForecastParams::alpha`] (1: the last displacement alone); an
//!   unmatched box, or one more than [`ForecastParams::max_gap`] frames after the
//!   previous output, stands still.
//! - [`Forecaster::at`] writes the boxes moved to frame `f`: each box plus its velocity
//!   times `f - frame`, at most [`ForecastParams::horizon`] frames ahead (never back).
//!
//! Constant velocity in the image, the centre only (a box keeps its size): the signs a
//! drone approaches grow slowly against how fast they slide across the view. `Copy`,
//! allocation-free, never panics; at most [`MAX_FORECAST`] boxes are kept per output
//! (the first ones shown).

use crate::geom::{BBox, Detection};

/// Boxes a [`Forecaster`] keeps per output.
pub const MAX_FORECAST: usize = 8;

/// How a [`Forecaster`] estimates and applies velocities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForecastParams {
    /// Weight of the newest displacement in the velocity, in (0, 1].
    pub alpha: f32,
    /// Least IoU for a new box to continue one of the previous output.
    pub min_iou: f32,
    /// Frames between two outputs beyond which no velocity is estimated.
    pub max_gap: u32,
    /// Frames ahead a box is moved at most.
    pub horizon: u32,
}

impl ForecastParams {
    /// The workbench's defaults (chosen on the budget policy's tuning videos; see the
    /// experiment records): half the newest displacement, half the previous velocity;
    /// IoU 0.1; gaps and horizon of 8 frames.
    pub const DEFAULT: Self = Self {
        alpha: 0.5,
        min_iou: 0.1,
        max_gap: 8,
        horizon: 8,
    };
}

impl Default for ForecastParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A constant-velocity forecaster over perception's outputs ([module docs](self)).
#[derive(Clone, Copy, Debug)]
pub struct Forecaster {
    params: ForecastParams,
    boxes: [Detection; MAX_FORECAST],
    velocity: [[f32; 2]; MAX_FORECAST],
    len: usize,
    frame: Option<u32>,
}

const NO_BOX: Detection = Detection {
    bbox: BBox {
        x1: 0.0,
        y1: 0.0,
        x2: 0.0,
        y2: 0.0,
    },
    score: 0.0,
    class: 0,
};

fn finite_or_zero(x: f32) -> f32 {
    if x.is_finite() { x } else { 0.0 }
}

impl Forecaster {
    /// A forecaster that has seen no output.
    pub const fn new(params: ForecastParams) -> Self {
        Self {
            params,
            boxes: [NO_BOX; MAX_FORECAST],
            velocity: [[0.0; 2]; MAX_FORECAST],
            len: 0,
            frame: None,
        }
    }

    /// Its parameters.
    pub const fn params(&self) -> ForecastParams {
        self.params
    }

    /// The frame of the last output, `None` before the first.
    pub const fn frame(&self) -> Option<u32> {
        self.frame
    }

    /// Forgets every output (a new video, a reset).
    pub fn reset(&mut self) {
        *self = Self::new(self.params);
    }

    /// The velocities (px per frame, x and y) of the last output's boxes, in the order
    /// shown.
    pub fn velocities(&self) -> &[[f32; 2]] {
        self.velocity.get(..self.len).unwrap_or(&[])
    }

    /// Takes the output of frame `frame`: the boxes it shows. Outputs come in
    /// processing order; one for a frame not after the previous output's has no
    /// velocity.
    pub fn update(&mut self, frame: u32, shown: &[Detection]) {
        let gap = self.frame.and_then(|p| frame.checked_sub(p)).unwrap_or(0);
        let usable = gap > 0 && gap <= self.params.max_gap;
        let g = gap as f32;
        let mut boxes = [NO_BOX; MAX_FORECAST];
        let mut velocity = [[0.0f32; 2]; MAX_FORECAST];
        let mut len = 0;
        for ((d, nb), nv) in shown.iter().zip(&mut boxes).zip(&mut velocity) {
            *nb = *d;
            len += 1;
            if !usable {
                continue;
            }
            let mut best: Option<(f32, &Detection, [f32; 2])> = None;
            for (q, v) in self
                .boxes
                .iter()
                .zip(&self.velocity)
                .take(self.len)
                .filter(|(q, _)| q.class == d.class)
            {
                let moved = q.bbox.translated(v[0] * g, v[1] * g);
                let iou = moved.iou(&d.bbox).max(q.bbox.iou(&d.bbox));
                if iou >= self.params.min_iou && best.is_none_or(|b| iou > b.0) {
                    best = Some((iou, q, *v));
                }
            }
            if let Some((_, q, v)) = best {
                let (cx, cy) = d.bbox.center();
                let (qx, qy) = q.bbox.center();
                let a = self.params.alpha;
                *nv = [
                    finite_or_zero(a * (cx - qx) / g + (1.0 - a) * v[0]),
                    finite_or_zero(a * (cy - qy) / g + (1.0 - a) * v[1]),
                ];
            }
        }
        self.boxes = boxes;
        self.velocity = velocity;
        self.len = len;
        self.frame = Some(frame);
    }

    /// Writes the last output's boxes moved to frame `frame` into `out` (as many as fit)
    /// and returns how many it wrote. A frame at or before the output's own gets the
    /// boxes as shown.
    pub fn at(&self, frame: u32, out: &mut [Detection]) -> usize {
        let ahead = self
            .frame
            .and_then(|p| frame.checked_sub(p))
            .unwrap_or(0)
            .min(self.params.horizon) as f32;
        let mut n = 0;
        for ((d, v), o) in self
            .boxes
            .iter()
            .zip(&self.velocity)
            .take(self.len)
            .zip(out.iter_mut())
        {
            *o = Detection {
                bbox: d.bbox.translated(v[0] * ahead, v[1] * ahead),
                ..*d
            };
            n += 1;
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x: f32, y: f32, class: u16) -> Detection {
        Detection {
            bbox: BBox::new(x, y, x + 20.0, y + 20.0),
            score: 0.9,
            class,
        }
    }

    fn one(f: &Forecaster, frame: u32) -> Detection {
        let mut out = [NO_BOX; 2];
        assert_eq!(f.at(frame, &mut out), 1);
        out[0]
    }

    #[test]
    fn a_box_moving_at_constant_speed_is_forecast_where_it_will_be() {
        let mut f = Forecaster::new(ForecastParams {
            alpha: 1.0,
            ..ForecastParams::DEFAULT
        });
        // 5 px per frame right, 2 down; outputs every 2 frames
        for t in [0u32, 2, 4] {
            f.update(t, &[det(5.0 * t as f32, 2.0 * t as f32, 1)]);
        }
        assert_eq!(f.velocities(), &[[5.0, 2.0]]);
        let d = one(&f, 7);
        assert_eq!(d.bbox, det(35.0, 14.0, 1).bbox);
        assert_eq!((d.score, d.class), (0.9, 1));
        // never back in time, never beyond the horizon
        assert_eq!(one(&f, 3).bbox, det(20.0, 8.0, 1).bbox);
        assert_eq!(one(&f, 4 + 100).bbox, det(20.0 + 40.0, 8.0 + 16.0, 1).bbox);
    }

    #[test]
    fn smoothing_classes_gaps_and_unmatched_boxes() {
        let mut f = Forecaster::new(ForecastParams::DEFAULT); // alpha 0.5
        f.update(0, &[det(0.0, 0.0, 1), det(100.0, 0.0, 2)]);
        // first displacement: half of it
        f.update(1, &[det(4.0, 0.0, 1), det(100.0, 0.0, 2)]);
        assert_eq!(f.velocities(), &[[2.0, 0.0], [0.0, 0.0]]);
        f.update(2, &[det(8.0, 0.0, 1), det(104.0, 0.0, 2)]);
        assert_eq!(f.velocities(), &[[3.0, 0.0], [2.0, 0.0]]);
        // a box of another class where the class-1 box was: no match, no velocity
        f.update(3, &[det(11.0, 0.0, 3)]);
        assert_eq!(f.velocities(), &[[0.0, 0.0]]);
        // an output too long after the previous: no velocity
        f.update(4, &[det(11.0, 0.0, 3)]);
        f.update(4 + 9, &[det(14.0, 0.0, 3)]);
        assert_eq!(f.velocities(), &[[0.0, 0.0]]);
        // the same frame again: no velocity, no division by zero
        f.update(13, &[det(20.0, 0.0, 3)]);
        assert_eq!(f.velocities(), &[[0.0, 0.0]]);
        // nothing shown
        f.update(14, &[]);
        assert!(f.velocities().is_empty());
        let mut out = [NO_BOX; 4];
        assert_eq!(f.at(20, &mut out), 0);
        f.reset();
        assert_eq!(f.frame(), None);
    }

    #[test]
    fn more_boxes_than_kept_and_than_room_and_bad_numbers_do_not_panic() {
        let mut f = Forecaster::new(ForecastParams::DEFAULT);
        let many: [Detection; 12] = core::array::from_fn(|i| det(30.0 * i as f32, 0.0, 0));
        f.update(0, &many);
        f.update(1, &many);
        assert_eq!(f.velocities().len(), MAX_FORECAST);
        let mut out = [NO_BOX; 3];
        assert_eq!(f.at(2, &mut out), 3);
        let nan = Detection {
            bbox: BBox::new(f32::NAN, 0.0, f32::INFINITY, 20.0),
            ..det(0.0, 0.0, 0)
        };
        f.update(2, &[nan]);
        f.update(3, &[nan]);
        assert!(f.velocities().iter().flatten().all(|v| v.is_finite()));
        assert_eq!(f.at(u32::MAX, &mut out), 1);
    }
}
