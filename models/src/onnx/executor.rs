//! The ONNX Runtime executor. It lives in [`frugal_runtime::onnx`] (the runtime's
//! `onnx` feature), so the executor the Pareto stage measures is the one that flies;
//! this module re-exports it and tests it against the tch model.
pub use frugal_runtime::cnn::resize_bilinear;
pub use frugal_runtime::onnx::{
    BACKBONE_RPN_FILE, BackboneOutputs, GlueSpec, OrtDetector, OrtError, ROI_HEAD_FILE, StageTimes,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::onnx::export_detector;
    use crate::testing::tiny_model;
    use frugal_runtime::FrameRef;

    /// A deterministic frame with some structure (gradients and a bright square).
    fn frame(w: u32, h: u32, k: u32) -> Vec<u8> {
        let mut px = Vec::with_capacity((w * h * 3) as usize);
        for y in 0..h {
            for x in 0..w {
                let inside = (x + k * 3) % w > 10 && (x + k * 3) % w < 26 && y > 8 && y < 24;
                let v = if inside {
                    240
                } else {
                    ((x * 7 + y * 3 + k * 11) % 200) as u8 as u32
                };
                px.extend([v as u8, (v / 2) as u8, (255 - v) as u8]);
            }
        }
        px
    }

    #[test]
    fn ort_executor_matches_tch_raw_outputs_and_detections() {
        let model = tiny_model(11, &[(8, 2, 1), (16, 2, 1)]);
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (64u32, 48u32);
        export_detector(&model, h as usize, w as usize, dir.path()).unwrap();
        let mut ort = OrtDetector::open(dir.path(), 1).unwrap();
        assert_eq!(ort.spec().num_classes, 3);
        let frames: Vec<_> = (0..6).map(|k| (w, h, frame(w, h, k))).collect();
        let r = crate::onnx::parity(&model, &mut ort, &frames).unwrap();
        assert_eq!(r.frames, 6);
        assert!(
            r.max_raw_diff < 1e-4,
            "raw outputs differ by {}",
            r.max_raw_diff
        );
        assert!(
            r.tch_detections > 0,
            "no detections to compare: make the test frames richer"
        );
        assert!(r.agrees(1e-4), "{r:?}");
    }

    #[test]
    fn bad_files_give_clear_errors() {
        let model = tiny_model(5, &[(8, 2, 1), (16, 2, 1)]);
        let dir = tempfile::tempdir().unwrap();
        let files = export_detector(&model, 32, 32, dir.path()).unwrap();
        let msg =
            |r: Result<OrtDetector, OrtError>| r.err().map(|e| e.to_string()).unwrap_or_default();

        // a frame with no pixels
        let mut ok = OrtDetector::open(dir.path(), 1).unwrap();
        if let Some(empty) = FrameRef::new(0, 32, &[]) {
            let e = ok.detect(empty).unwrap_err().to_string();
            assert!(e.contains("0×32") && e.contains("32×32"), "{e}");
        }
        // a frame of another size is resized, not refused
        let px = vec![0u8; 40 * 32 * 3];
        assert!(ok.detect(FrameRef::new(40, 32, &px).unwrap()).is_ok());

        // missing file
        let empty = tempfile::tempdir().unwrap();
        let e = msg(OrtDetector::open(empty.path(), 1));
        assert!(
            e.contains(BACKBONE_RPN_FILE) && e.contains("no such file"),
            "{e}"
        );

        // truncated file
        let bytes = std::fs::read(&files.roi_head).unwrap();
        std::fs::write(&files.roi_head, &bytes[..bytes.len() / 2]).unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(
            e.contains(ROI_HEAD_FILE) && e.contains("not a loadable ONNX model"),
            "{e}"
        );

        // not ONNX at all
        std::fs::write(&files.roi_head, b"this is not a protobuf").unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(e.contains(ROI_HEAD_FILE), "{e}");

        // a valid ONNX file whose inputs do not match: the backbone graph in the head's place
        std::fs::copy(&files.backbone_rpn, &files.roi_head).unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(e.contains("inputs are [\"image\"]"), "{e}");

        // graphs from two different exports (metadata differs)
        let other = tempfile::tempdir().unwrap();
        let f2 = export_detector(&model, 48, 32, other.path()).unwrap();
        std::fs::copy(&f2.roi_head, &files.roi_head).unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(e.contains("not exported together"), "{e}");
    }
}
