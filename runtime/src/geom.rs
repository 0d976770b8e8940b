//! Boxes, detections, frames and the detector trait shared by every stage.

/// A sign class index (into the dataset's class list).
pub type ClassId = u16;

/// A detector variant index (into the bundle's variant table).
pub type VariantId = u16;

/// An axis-aligned box in pixel coordinates, `x1 <= x2`, `y1 <= y2`; `x2`/`y2` are
/// exclusive edges, so a box covering pixel columns 10..=19 has `x1 = 10, x2 = 20`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct BBox {
    /// Left edge.
    pub x1: f32,
    /// Top edge.
    pub y1: f32,
    /// Right edge (exclusive).
    pub x2: f32,
    /// Bottom edge (exclusive).
    pub y2: f32,
}

impl BBox {
    /// A box from its corners.
    pub const fn new(x1: f32, y1: f32, x2: f32, y2: f32) -> Self {
        Self { x1, y1, x2, y2 }
    }

    /// A box from its top-left corner and size.
    pub const fn from_xywh(x: f32, y: f32, w: f32, h: f32) -> Self {
        Self::new(x, y, x + w, y + h)
    }

    /// Width (0 for a degenerate box).
    pub fn width(&self) -> f32 {
        let w = self.x2 - self.x1;
        if w > 0.0 { w } else { 0.0 }
    }

    /// Height (0 for a degenerate box).
    pub fn height(&self) -> f32 {
        let h = self.y2 - self.y1;
        if h > 0.0 { h } else { 0.0 }
    }

    /// Area (0 for a degenerate box).
    pub fn area(&self) -> f32 {
        self.width() * self.height()
    }

    /// The same box moved by `(dx, dy)`.
    pub const fn translated(&self, dx: f32, dy: f32) -> Self {
        Self::new(self.x1 + dx, self.y1 + dy, self.x2 + dx, self.y2 + dy)
    }

    /// Centre point `(cx, cy)`.
    pub fn center(&self) -> (f32, f32) {
        ((self.x1 + self.x2) * 0.5, (self.y1 + self.y2) * 0.5)
    }

    /// True when every coordinate is finite and the box has positive area.
    pub fn is_valid(&self) -> bool {
        self.x1.is_finite()
            && self.y1.is_finite()
            && self.x2.is_finite()
            && self.y2.is_finite()
            && self.x2 > self.x1
            && self.y2 > self.y1
    }

    /// The overlap of two boxes (degenerate when they do not overlap).
    pub fn intersection(&self, other: &BBox) -> BBox {
        BBox::new(
            self.x1.max(other.x1),
            self.y1.max(other.y1),
            self.x2.min(other.x2),
            self.y2.min(other.y2),
        )
    }

    /// Intersection over union in `[0, 1]`; 0 when either box is degenerate.
    pub fn iou(&self, other: &BBox) -> f32 {
        let inter = self.intersection(other).area();
        let union = self.area() + other.area() - inter;
        if union > 0.0 { inter / union } else { 0.0 }
    }

    /// The box clipped to a `width × height` image.
    pub fn clip(&self, width: f32, height: f32) -> BBox {
        BBox::new(
            self.x1.clamp(0.0, width),
            self.y1.clamp(0.0, height),
            self.x2.clamp(0.0, width),
            self.y2.clamp(0.0, height),
        )
    }
}

/// One detection: a class, a box and the detector's confidence score.
///
/// The score's scale depends on the detector family (a softmax probability in `[0, 1]`
/// for the CNN family, a signed SVM margin for the HoG family); the policy bundle's
/// confidence buckets are defined on that same scale, per family.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Detection {
    /// The box.
    pub bbox: BBox,
    /// Confidence on the family's score scale.
    pub score: f32,
    /// The class.
    pub class: ClassId,
}

/// A borrowed interleaved RGB8 frame, row-major, `width * height * 3` bytes.
#[derive(Clone, Copy, Debug)]
pub struct FrameRef<'a> {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, `RGBRGB…`, row by row.
    pub rgb: &'a [u8],
}

impl<'a> FrameRef<'a> {
    /// A frame view, or `None` when the slice length does not match the size.
    pub fn new(width: u32, height: u32, rgb: &'a [u8]) -> Option<Self> {
        let need = (width as usize)
            .checked_mul(height as usize)?
            .checked_mul(3)?;
        (rgb.len() == need).then_some(Self { width, height, rgb })
    }
}

/// Anything that turns a frame into detections: the tch CNN, its ONNX Runtime
/// executor, the HoG + SVM pipeline.
///
/// Detections are written into a caller-provided slice, so the trait is usable without
/// an allocator; the return value is how many were written (the best `out.len()` when
/// there are more).
pub trait Detector {
    /// What can go wrong.
    type Error;
    /// Detect signs in `frame`, writing at most `out.len()` detections sorted by score,
    /// highest first.
    fn detect(&mut self, frame: FrameRef<'_>, out: &mut [Detection]) -> Result<usize, Self::Error>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_identical_disjoint_and_half_overlapping_boxes() {
        let a = BBox::new(0.0, 0.0, 10.0, 10.0);
        assert_eq!(a.iou(&a), 1.0);
        assert_eq!(a.iou(&BBox::new(20.0, 20.0, 30.0, 30.0)), 0.0);
        let b = BBox::new(5.0, 0.0, 15.0, 10.0);
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-6);
        assert_eq!(a.iou(&BBox::new(3.0, 3.0, 3.0, 8.0)), 0.0);
    }

    #[test]
    fn frame_view_checks_its_length() {
        let px = [0u8; 12];
        assert!(FrameRef::new(2, 2, &px).is_some());
        assert!(FrameRef::new(3, 2, &px).is_none());
        assert!(FrameRef::new(u32::MAX, u32::MAX, &px).is_none());
    }
}
