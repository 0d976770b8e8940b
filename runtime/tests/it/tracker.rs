use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{GrayImage, Pyramid, Tracker, TrackerParams};

#[test]
fn probe() {
    let clip = make_clip(&ClipSpec::standard(7, 40));
    let (w, h) = (clip.width, clip.height);
    let need = Pyramid::required_len(w, h, 3).unwrap();
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);
    let mut prev = Pyramid::new(&mut wa, w, h, 3).unwrap();
    let mut next = Pyramid::new(&mut wb, w, h, 3).unwrap();
    let mut t = Tracker::<64>::new(TrackerParams::DEFAULT);
    for start in [0usize, 10, 20, 29] {
        prev.build(&GrayImage::new(&clip.frames[start], w, h, w).unwrap())
            .unwrap();
        let n = t.init(&prev, clip.boxes[start]).unwrap();
        eprint!("start {start} n={n}:");
        for f in start + 1..(start + 11).min(clip.frames.len()) {
            next.build(&GrayImage::new(&clip.frames[f], w, h, w).unwrap())
                .unwrap();
            match t.track(&prev, &next) {
                Ok(o) => eprint!(" {:.3}/{}", o.bbox.iou(&clip.boxes[f]), o.points),
                Err(e) => eprint!(" ERR {e}"),
            }
            std::mem::swap(&mut prev, &mut next);
        }
        eprintln!();
    }
}
