//! A checked view of an RGB8 frame and window resampling.

use crate::error::{Error, Result};
use frugal_runtime::{BBox, FrameRef};

/// A borrowed interleaved RGB8 image whose length has been checked.
#[derive(Clone, Copy, Debug)]
pub struct Rgb<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height * 3` bytes, row-major.
    pub data: &'a [u8],
}

impl<'a> Rgb<'a> {
    /// A view of `data` as a `width × height` RGB8 image; an error when the length
    /// does not match.
    pub fn new(width: usize, height: usize, data: &'a [u8]) -> Result<Self> {
        let expected = width.checked_mul(height).and_then(|n| n.checked_mul(3));
        if expected != Some(data.len()) {
            return Err(Error::FrameSize {
                width: u32::try_from(width).unwrap_or(u32::MAX),
                height: u32::try_from(height).unwrap_or(u32::MAX),
                len: data.len(),
                expected: expected.unwrap_or(usize::MAX),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// A checked view of a runtime frame.
    pub fn from_frame(frame: FrameRef<'a>) -> Result<Self> {
        Self::new(frame.width as usize, frame.height as usize, frame.rgb)
    }

    /// Resample the part of the image under `bbox` to a `size × size` RGB window
    /// (interleaved `f32` in `0..=255`), bilinearly, sampling at pixel centres and
    /// clamping at the image border. `out` is resized to `size * size * 3`.
    pub fn window(&self, bbox: &BBox, size: usize, out: &mut Vec<f32>) {
        out.clear();
        out.resize(size * size * 3, 0.0);
        if self.width == 0 || self.height == 0 || size == 0 {
            return;
        }
        let (w, h) = (self.width, self.height);
        let sx = (bbox.x2 - bbox.x1) / size as f32;
        let sy = (bbox.y2 - bbox.y1) / size as f32;
        // Per output column: the two source columns and the weight of the second.
        let cols: Vec<(usize, usize, f32)> = (0..size)
            .map(|i| tap(bbox.x1 + (i as f32 + 0.5) * sx - 0.5, w))
            .collect();
        for j in 0..size {
            let (y0, y1, fy) = tap(bbox.y1 + (j as f32 + 0.5) * sy - 0.5, h);
            let r0 = &self.data[y0 * w * 3..(y0 + 1) * w * 3];
            let r1 = &self.data[y1 * w * 3..(y1 + 1) * w * 3];
            let dst = &mut out[j * size * 3..(j + 1) * size * 3];
            for (i, &(x0, x1, fx)) in cols.iter().enumerate() {
                for c in 0..3 {
                    let a = r0[x0 * 3 + c] as f32 * (1.0 - fx) + r0[x1 * 3 + c] as f32 * fx;
                    let b = r1[x0 * 3 + c] as f32 * (1.0 - fx) + r1[x1 * 3 + c] as f32 * fx;
                    dst[i * 3 + c] = a * (1.0 - fy) + b * fy;
                }
            }
        }
    }
}

/// The two neighbouring source indices of position `p` in `0..n` and the weight of
/// the second, clamped at the borders (non-finite positions clamp to 0).
fn tap(p: f32, n: usize) -> (usize, usize, f32) {
    let max = (n - 1) as f32;
    let p = if p.is_finite() {
        p.clamp(0.0, max)
    } else {
        0.0
    };
    let i0 = p.floor() as usize;
    let i1 = (i0 + 1).min(n - 1);
    (i0, i1, p - i0 as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_is_checked() {
        assert!(Rgb::new(2, 2, &[0u8; 12]).is_ok());
        assert!(matches!(
            Rgb::new(3, 2, &[0u8; 12]),
            Err(Error::FrameSize { expected: 18, .. })
        ));
        assert!(Rgb::new(usize::MAX, 3, &[]).is_err());
    }

    #[test]
    fn window_of_the_whole_image_at_its_own_size_is_the_image() {
        let px: Vec<u8> = (0..4 * 4 * 3).map(|i| (i * 5) as u8).collect();
        let img = Rgb::new(4, 4, &px).unwrap();
        let mut out = Vec::new();
        img.window(&BBox::new(0.0, 0.0, 4.0, 4.0), 4, &mut out);
        for (a, b) in out.iter().zip(&px) {
            assert!((a - *b as f32).abs() < 1e-4);
        }
        // A box far outside the image clamps instead of panicking.
        img.window(&BBox::new(-100.0, 50.0, f32::NAN, 1e9), 8, &mut out);
        assert_eq!(out.len(), 8 * 8 * 3);
    }
}
