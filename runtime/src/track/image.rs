//! Borrowed grayscale images, RGB → gray, and image pyramids over caller workspaces.

use super::TrackError;
use crate::geom::FrameRef;

/// A borrowed 8-bit grayscale image, row-major with a row stride in bytes.
#[derive(Clone, Copy, Debug)]
pub struct GrayImage<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> GrayImage<'a> {
    /// A view of `data`; fails when the sizes are zero, `stride < width`, or `data`
    /// is shorter than `(height − 1) · stride + width`.
    pub fn new(
        data: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, TrackError> {
        if width == 0 || height == 0 || stride < width {
            return Err(TrackError::BadImage);
        }
        let need = (height - 1)
            .checked_mul(stride)
            .and_then(|v| v.checked_add(width))
            .ok_or(TrackError::BadImage)?;
        if data.len() < need {
            return Err(TrackError::BadImage);
        }
        Ok(Self {
            data,
            width,
            height,
            stride,
        })
    }

    /// Width in pixels.
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub const fn height(&self) -> usize {
        self.height
    }

    /// Row stride in bytes.
    pub const fn stride(&self) -> usize {
        self.stride
    }

    /// Row `y` (exactly `width` bytes).
    #[inline]
    pub fn row(&self, y: usize) -> Option<&'a [u8]> {
        let start = y.checked_mul(self.stride)?;
        self.data.get(start..start.checked_add(self.width)?)
    }

    /// Pixel `(x, y)`.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> Option<u8> {
        if x >= self.width {
            return None;
        }
        self.data
            .get(y.checked_mul(self.stride)?.checked_add(x)?)
            .copied()
    }

    /// Pixel at clamped coordinates (border replication); 0 only for an empty image.
    #[inline]
    pub fn clamped(&self, x: isize, y: isize) -> u8 {
        let x = x.clamp(0, self.width as isize - 1) as usize;
        let y = y.clamp(0, self.height as isize - 1) as usize;
        self.get(x, y).unwrap_or(0)
    }
}

/// Converts an RGB8 frame to gray (ITU-R BT.601 weights 0.299, 0.587, 0.114 in 14-bit
/// fixed point, rounded) into `out` (at least `width · height` bytes; stride = width).
pub fn rgb_to_gray<'o>(
    frame: &FrameRef<'_>,
    out: &'o mut [u8],
) -> Result<GrayImage<'o>, TrackError> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let n = w.checked_mul(h).ok_or(TrackError::BadImage)?;
    if frame.rgb.len() != n.checked_mul(3).ok_or(TrackError::BadImage)? {
        return Err(TrackError::BadImage);
    }
    let dst = out.get_mut(..n).ok_or(TrackError::WorkspaceTooSmall)?;
    for (g, px) in dst.iter_mut().zip(frame.rgb.chunks_exact(3)) {
        if let [r, gr, b] = *px {
            let y = 4899 * u32::from(r) + 9617 * u32::from(gr) + 1868 * u32::from(b) + (1 << 13);
            *g = (y >> 14) as u8;
        }
    }
    GrayImage::new(out, w, h, w)
}

/// Most pyramid levels.
pub const MAX_LEVELS: usize = 5;

/// Sizes of the levels of a `width × height` pyramid: level `l + 1` is
/// `⌈w_l / 2⌉ × ⌈h_l / 2⌉`.
fn level_dims(width: usize, height: usize, levels: usize) -> [(usize, usize); MAX_LEVELS] {
    let mut dims = [(0, 0); MAX_LEVELS];
    let (mut w, mut h) = (width, height);
    for d in dims.iter_mut().take(levels) {
        *d = (w, h);
        w = w.div_ceil(2);
        h = h.div_ceil(2);
    }
    dims
}

/// A Gaussian image pyramid stored in a caller-provided byte workspace.
///
/// Level 0 is a copy of the frame (stride = width); level `l + 1` is level `l`
/// smoothed with the separable `[1 2 1] / 4` kernel in each direction (borders
/// replicated) and sampled at even pixels, so level-`l + 1` pixel `(x, y)` sits at
/// level-`l` pixel `(2x, 2y)`.
#[derive(Debug)]
pub struct Pyramid<'w> {
    buf: &'w mut [u8],
    levels: usize,
    dims: [(usize, usize); MAX_LEVELS],
    offsets: [usize; MAX_LEVELS],
}

impl<'w> Pyramid<'w> {
    /// Bytes of workspace a `width × height` pyramid with `levels` levels needs
    /// (`None` when `levels` is 0 or above [`MAX_LEVELS`], or on overflow).
    pub fn required_len(width: usize, height: usize, levels: usize) -> Option<usize> {
        if levels == 0 || levels > MAX_LEVELS || width == 0 || height == 0 {
            return None;
        }
        level_dims(width, height, levels)
            .iter()
            .take(levels)
            .try_fold(0usize, |acc, (w, h)| acc.checked_add(w.checked_mul(*h)?))
    }

    /// An (unbuilt, all-zero) pyramid over `buf`.
    pub fn new(
        buf: &'w mut [u8],
        width: usize,
        height: usize,
        levels: usize,
    ) -> Result<Self, TrackError> {
        let need = Self::required_len(width, height, levels).ok_or(TrackError::BadImage)?;
        if buf.len() < need {
            return Err(TrackError::WorkspaceTooSmall);
        }
        let dims = level_dims(width, height, levels);
        let mut offsets = [0; MAX_LEVELS];
        let mut acc = 0;
        for (o, (w, h)) in offsets.iter_mut().zip(dims.iter()).take(levels) {
            *o = acc;
            acc += w * h;
        }
        Ok(Self {
            buf,
            levels,
            dims,
            offsets,
        })
    }

    /// Number of levels.
    pub const fn levels(&self) -> usize {
        self.levels
    }

    /// Width of level 0.
    pub const fn width(&self) -> usize {
        self.dims[0].0
    }

    /// Height of level 0.
    pub const fn height(&self) -> usize {
        self.dims[0].1
    }

    /// Level `l` as an image.
    pub fn level(&self, l: usize) -> Option<GrayImage<'_>> {
        if l >= self.levels {
            return None;
        }
        let (w, h) = *self.dims.get(l)?;
        let off = *self.offsets.get(l)?;
        GrayImage::new(self.buf.get(off..off + w * h)?, w, h, w).ok()
    }

    /// Fills the pyramid from `frame`, which must have level 0's size.
    pub fn build(&mut self, frame: &GrayImage<'_>) -> Result<(), TrackError> {
        let (w0, h0) = (self.width(), self.height());
        if frame.width() != w0 || frame.height() != h0 {
            return Err(TrackError::SizeMismatch);
        }
        let level0 = self
            .buf
            .get_mut(..w0 * h0)
            .ok_or(TrackError::WorkspaceTooSmall)?;
        for (y, dst) in level0.chunks_exact_mut(w0).enumerate() {
            dst.copy_from_slice(frame.row(y).ok_or(TrackError::BadImage)?);
        }
        self.build_upper()
    }

    /// Fills the pyramid from an RGB frame of level 0's size: [`rgb_to_gray`] straight
    /// into level 0 (no separate gray image, no copy), then the upper levels. The same
    /// pyramid as `rgb_to_gray` followed by [`Pyramid::build`].
    pub fn build_rgb(&mut self, frame: &FrameRef<'_>) -> Result<(), TrackError> {
        let (w0, h0) = (self.width(), self.height());
        if (frame.width as usize, frame.height as usize) != (w0, h0) {
            return Err(TrackError::SizeMismatch);
        }
        let level0 = self
            .buf
            .get_mut(..w0 * h0)
            .ok_or(TrackError::WorkspaceTooSmall)?;
        rgb_to_gray(frame, level0)?;
        self.build_upper()
    }

    /// Levels 1 and up from level 0.
    fn build_upper(&mut self) -> Result<(), TrackError> {
        for l in 1..self.levels {
            let (sw, sh) = *self.dims.get(l - 1).ok_or(TrackError::BadImage)?;
            let (dw, dh) = *self.dims.get(l).ok_or(TrackError::BadImage)?;
            let soff = *self.offsets.get(l - 1).ok_or(TrackError::BadImage)?;
            let doff = *self.offsets.get(l).ok_or(TrackError::BadImage)?;
            let (head, tail) = self.buf.split_at_mut(doff);
            let src = head
                .get(soff..soff + sw * sh)
                .ok_or(TrackError::WorkspaceTooSmall)?;
            let dst = tail
                .get_mut(..dw * dh)
                .ok_or(TrackError::WorkspaceTooSmall)?;
            let src = GrayImage::new(src, sw, sh, sw)?;
            downsample(&src, dst, dw);
        }
        Ok(())
    }
}

/// One output pixel of the `[1 2 1]²/16` half-resolution filter, borders replicated.
#[inline]
fn down_px(src: &GrayImage<'_>, x: usize, y: usize) -> u8 {
    let (cx, cy) = (2 * x as isize, 2 * y as isize);
    let mut sum = 0u32;
    for (dy, wy) in [(-1isize, 1u32), (0, 2), (1, 1)] {
        for (dx, wx) in [(-1isize, 1u32), (0, 2), (1, 1)] {
            sum += wy * wx * u32::from(src.clamped(cx + dx, cy + dy));
        }
    }
    ((sum + 8) >> 4) as u8
}

/// Widest row the fast interior path of [`downsample`] takes (a stack row of sums).
const ROW_CHUNK: usize = 1024;

fn downsample(src: &GrayImage<'_>, dst: &mut [u8], dw: usize) {
    let (sw, sh) = (src.width(), src.height());
    for (y, drow) in dst.chunks_exact_mut(dw).enumerate() {
        let interior_rows = y >= 1 && 2 * y + 1 < sh;
        let rows = (
            src.row((2 * y).wrapping_sub(1)),
            src.row(2 * y),
            src.row(2 * y + 1),
        );
        match (interior_rows, rows) {
            (true, (Some(r0), Some(r1), Some(r2))) if sw <= ROW_CHUNK => {
                // vertical [1 2 1] into a row of sums (vectorises), then horizontal
                // [1 2 1] over pairs of sums: output x >= 1 reads sums 2x-1, 2x, 2x+1
                let mut v = [0u16; ROW_CHUNK];
                for (((o, a), b), c) in v.iter_mut().zip(r0).zip(r1).zip(r2) {
                    *o = u16::from(*a) + 2 * u16::from(*b) + u16::from(*c);
                }
                let sums = v.get(1..sw).unwrap_or(&[]);
                let pairs = sums.chunks_exact(2);
                let mut done = 1;
                for (d, (p0, p1)) in drow
                    .iter_mut()
                    .skip(1)
                    .zip(pairs.clone().zip(pairs.skip(1)))
                {
                    if let ([a, b], [c, _]) = (p0, p1) {
                        *d = ((u32::from(*a) + 2 * u32::from(*b) + u32::from(*c) + 8) >> 4) as u8;
                    }
                    done += 1;
                }
                for (x, d) in drow.iter_mut().enumerate() {
                    if x == 0 || x >= done {
                        *d = down_px(src, x, y);
                    }
                }
            }
            (true, (Some(r0), Some(r1), Some(r2))) => {
                // Output x >= 1 whose 3-wide window [2x-1, 2x+1] lies inside the row.
                let (a, b, c) = (
                    r0.get(1..).unwrap_or(&[]),
                    r1.get(1..).unwrap_or(&[]),
                    r2.get(1..).unwrap_or(&[]),
                );
                let inner = a
                    .windows(3)
                    .step_by(2)
                    .zip(b.windows(3).step_by(2))
                    .zip(c.windows(3).step_by(2));
                let mut done = 1;
                for (d, ((wa, wb), wc)) in drow.iter_mut().skip(1).zip(inner) {
                    if let ([a0, a1, a2], [b0, b1, b2], [c0, c1, c2]) = (wa, wb, wc) {
                        let s = |p: &u8, q: &u8, r: &u8| {
                            u32::from(*p) + 2 * u32::from(*q) + u32::from(*r)
                        };
                        let v = s(a0, a1, a2) + 2 * s(b0, b1, b2) + s(c0, c1, c2);
                        *d = ((v + 8) >> 4) as u8;
                    }
                    done += 1;
                }
                for (x, d) in drow.iter_mut().enumerate() {
                    if x == 0 || x >= done {
                        *d = down_px(src, x, y);
                    }
                }
            }
            _ => {
                for (x, d) in drow.iter_mut().enumerate() {
                    *d = down_px(src, x, y);
                }
            }
        }
        let _ = sw;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn building_from_rgb_is_gray_then_build() {
        let (w, h) = (37, 23);
        let rgb: std::vec::Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
        let frame = FrameRef::new(w as u32, h as u32, &rgb).unwrap();
        let mut gray = std::vec![0u8; w * h];
        let g = rgb_to_gray(&frame, &mut gray).unwrap();
        let need = Pyramid::required_len(w, h, 3).unwrap();
        let (mut a, mut b) = (std::vec![0u8; need], std::vec![1u8; need]);
        Pyramid::new(&mut a, w, h, 3).unwrap().build(&g).unwrap();
        Pyramid::new(&mut b, w, h, 3)
            .unwrap()
            .build_rgb(&frame)
            .unwrap();
        assert_eq!(a, b);
        let small = FrameRef::new(3, 3, rgb.get(..27).unwrap()).unwrap();
        let mut p = Pyramid::new(&mut b, w, h, 3).unwrap();
        assert_eq!(p.build_rgb(&small), Err(TrackError::SizeMismatch));
    }

    /// Every output pixel of [`downsample`] (both interior paths and the borders)
    /// equals the filter's definition, [`down_px`], on noisy images of odd and even
    /// sizes, narrow and wider than [`ROW_CHUNK`].
    #[test]
    fn downsample_is_the_filter_everywhere() {
        let mut state = 0x9e37_79b9_u32;
        for (w, h) in [
            (480, 270),
            (481, 271),
            (7, 5),
            (2, 2),
            (1, 1),
            (3, 1),
            (1100, 9),
        ] {
            let px: std::vec::Vec<u8> = (0..w * h)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    (state >> 24) as u8
                })
                .collect();
            let src = GrayImage::new(&px, w, h, w).unwrap();
            let (dw, dh) = (w.div_ceil(2), h.div_ceil(2));
            let mut dst = std::vec![0u8; dw * dh];
            downsample(&src, &mut dst, dw);
            for (i, d) in dst.iter().enumerate() {
                let (x, y) = (i % dw, i / dw);
                assert_eq!(*d, down_px(&src, x, y), "{w}x{h} at ({x}, {y})");
            }
        }
    }
}
