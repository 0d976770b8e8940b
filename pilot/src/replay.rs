//! Replayed detections (`--detections FILE`): per-frame sign detections read from a
//! file instead of running the bundle's ONNX variants, so that the navigation and
//! MAVLink chain can be run and debugged deterministically on any footage.
//!
//! The file holds JSON lines, one per frame that has detections (a frame without a
//! line has none); the pilot's own JSON output (`--json`) is such a file, and its
//! `{"summary": …}` line is skipped:
//!
//! ```json
//! {"frame":212,"decision":"detect","boxes":[{"class":0,"score":0.93,"box":[231.0,80.5,262.4,111.9]}],
//!  "confirm":[{"class":0,"score":0.97,"box":[231.0,80.5,262.4,111.9]}]}
//! ```
//!
//! `frame` is the frame's number in the input; `boxes` its detections (`box` is
//! `[x1, y1, x2, y2]` in pixels of the configured camera size); `decision`
//! `"track"` marks them as carried by a tracker (default `"detect"`); `confirm`, when
//! present, is what the reference variant reads when the navigator asks for a
//! confirmation on that frame (default: the frame's own boxes), `null` when the
//! perception has no reference detector to ask (the navigator then acts on its
//! sighting unconfirmed, as the simulator's ground-truth perception makes it). A
//! flight recorded with `frugal fly --record` writes its perception in this format
//! (`logs/percepts_<video>.jsonl`).
use frugal_nav::Percept;
use frugal_runtime::{BBox, Detection};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A detections file that cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct ReplayError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

#[derive(Clone, Debug, Default)]
struct ReplayFrame {
    detections: Vec<Detection>,
    tracked: bool,
    /// Absent: the frame's own boxes; `Some(None)`: no reference reading.
    confirm: Option<Option<Vec<Detection>>>,
}

/// The detections of a file, by frame number.
#[derive(Clone, Debug, Default)]
pub struct Replay {
    frames: HashMap<u64, ReplayFrame>,
}

fn boxes(value: &serde_json::Value) -> Result<Vec<Detection>, String> {
    let list = value.as_array().ok_or("boxes must be a list")?;
    list.iter()
        .map(|b| {
            let class = b
                .get("class")
                .and_then(serde_json::Value::as_u64)
                .and_then(|c| u16::try_from(c).ok())
                .ok_or("a box without a class (0..65535)")?;
            let score = b
                .get("score")
                .and_then(serde_json::Value::as_f64)
                .ok_or("a box without a score")? as f32;
            let corners: Vec<f32> = b
                .get("box")
                .and_then(serde_json::Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(serde_json::Value::as_f64)
                        .map(|v| v as f32)
                        .collect()
                })
                .unwrap_or_default();
            let [x1, y1, x2, y2] = corners[..] else {
                return Err("a box's `box` must be [x1, y1, x2, y2]".to_owned());
            };
            if !(x2 > x1 && y2 > y1 && score.is_finite()) {
                return Err(format!("box [{x1}, {y1}, {x2}, {y2}] is empty"));
            }
            Ok(Detection {
                bbox: BBox { x1, y1, x2, y2 },
                score,
                class,
            })
        })
        .collect()
}

impl Replay {
    /// Read `path`.
    pub fn read(path: &Path) -> Result<Self, ReplayError> {
        let err = |message: String| ReplayError {
            path: path.to_owned(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        let mut frames = HashMap::new();
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let at = |m: String| err(format!("line {}: {m}", i + 1));
            let value: serde_json::Value =
                serde_json::from_str(line).map_err(|e| at(e.to_string()))?;
            if value.get("summary").is_some() {
                continue;
            }
            let frame = value
                .get("frame")
                .and_then(serde_json::Value::as_u64)
                .ok_or_else(|| at("no frame number".into()))?;
            let detections = match value.get("boxes") {
                Some(b) => boxes(b).map_err(at)?,
                None => Vec::new(),
            };
            let tracked = match value.get("decision").and_then(serde_json::Value::as_str) {
                None | Some("detect") => false,
                Some("track") => true,
                Some(other) => {
                    return Err(at(format!(
                        "decision is `detect` or `track`, not `{other}`"
                    )));
                }
            };
            let confirm = match value.get("confirm") {
                None => None,
                Some(serde_json::Value::Null) => Some(None),
                Some(b) => Some(Some(boxes(b).map_err(at)?)),
            };
            let replay = ReplayFrame {
                detections,
                tracked,
                confirm,
            };
            if frames.insert(frame, replay).is_some() {
                return Err(at(format!("frame {frame} appears twice")));
            }
        }
        Ok(Self { frames })
    }

    /// What perception "sees" on frame number `frame` of the input.
    pub fn percept(&self, frame: u64) -> Percept {
        let f = self.frames.get(&frame);
        Percept {
            detections: f.map(|f| f.detections.clone()).unwrap_or_default(),
            compute_ms: 0.0,
            tracked: f.is_some_and(|f| f.tracked),
            int8_ms: 0.0,
            tracker_ms: 0.0,
        }
    }

    /// What the reference variant reads on frame number `frame`; `None` when the
    /// file says there is no reference reading (`"confirm": null`).
    pub fn confirm(&self, frame: u64) -> Option<Vec<Detection>> {
        match self.frames.get(&frame) {
            None => Some(Vec::new()),
            Some(f) => match &f.confirm {
                None => Some(f.detections.clone()),
                Some(read) => read.clone(),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_read_by_frame_and_bad_lines_name_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.jsonl");
        std::fs::write(
            &path,
            "{\"frame\":3,\"decision\":\"track\",\"boxes\":[{\"class\":1,\"score\":0.5,\"box\":[1,2,3,4]}]}\n\
             {\"frame\":4,\"boxes\":[],\"confirm\":[{\"class\":2,\"score\":0.9,\"box\":[0,0,8,8]}]}\n\
             {\"frame\":6,\"boxes\":[],\"confirm\":null}\n\
             {\"summary\":{}}\n",
        )
        .unwrap();
        let r = Replay::read(&path).unwrap();
        let p = r.percept(3);
        assert!(p.tracked);
        assert_eq!(p.detections.len(), 1);
        assert_eq!(p.detections[0].class, 1);
        assert_eq!(r.confirm(3), Some(p.detections));
        assert!(r.percept(4).detections.is_empty());
        assert_eq!(r.confirm(4).unwrap()[0].class, 2);
        assert_eq!(r.confirm(6), None);
        assert_eq!(r.confirm(5), Some(Vec::new()));
        assert_eq!(r.percept(5), Percept::default());
        std::fs::write(
            &path,
            "{\"frame\":1}\n{\"frame\":2,\"boxes\":[{\"class\":1}]}\n",
        )
        .unwrap();
        let e = Replay::read(&path).unwrap_err().to_string();
        assert!(e.contains("d.jsonl") && e.contains("line 2"), "{e}");
    }
}
