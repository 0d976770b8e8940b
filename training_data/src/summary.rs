//! Counts and box statistics of a dataset, as printed by `frugal data summary` and
//! `frugal run`, and serialisable to JSON.
use crate::{Dataset, Split};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt;

/// Box size statistics, in pixels (the box's `sqrt(w * h)`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SizeStats {
    /// Smallest.
    pub min: f32,
    /// Median.
    pub median: f32,
    /// Mean.
    pub mean: f32,
    /// Largest.
    pub max: f32,
}

impl SizeStats {
    fn of(mut v: Vec<f32>) -> Self {
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f32::total_cmp);
        Self {
            min: v[0],
            median: v[v.len() / 2],
            mean: v.iter().sum::<f32>() / v.len() as f32,
            max: v[v.len() - 1],
        }
    }
}

/// Counts of one group (a split, a scenario level or a class).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Row {
    /// Videos.
    pub videos: u32,
    /// Frames.
    pub frames: u64,
    /// Frames without any object.
    pub empty_frames: u64,
    /// Objects.
    pub objects: u64,
}

/// Everything `frugal data summary` prints.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Per split.
    pub splits: BTreeMap<String, Row>,
    /// Per scenario `clutter/light`, per split.
    pub scenarios: BTreeMap<String, BTreeMap<String, Row>>,
    /// Objects per class name, per split.
    pub classes: BTreeMap<String, BTreeMap<String, u64>>,
    /// Box sizes over all objects.
    pub box_size: SizeStats,
    /// Box widths.
    pub box_width: SizeStats,
    /// Box heights.
    pub box_height: SizeStats,
    /// How many frames have 0, 1, 2, … objects.
    pub objects_per_frame: BTreeMap<usize, u64>,
}

/// Summarise a dataset.
pub fn summary(ds: &Dataset) -> Summary {
    let mut s = Summary::default();
    for split in Split::ALL {
        s.splits.insert(split.name().into(), Row::default());
    }
    for c in &ds.classes {
        s.classes.insert(
            c.name.clone(),
            Split::ALL
                .iter()
                .map(|sp| (sp.name().to_owned(), 0))
                .collect(),
        );
    }
    let scenario = |v: u32| {
        ds.video(v)
            .map(|m| format!("{}/{}", m.clutter.name(), m.light.name()))
            .unwrap_or_else(|| "unknown".into())
    };
    for v in &ds.videos {
        let key = format!("{}/{}", v.clutter.name(), v.light.name());
        s.splits.entry(v.split.name().into()).or_default().videos += 1;
        s.scenarios
            .entry(key)
            .or_default()
            .entry(v.split.name().into())
            .or_default()
            .videos += 1;
    }
    let (mut sizes, mut widths, mut heights) = (Vec::new(), Vec::new(), Vec::new());
    for f in &ds.frames {
        let split = f.split.name().to_owned();
        let scen = scenario(f.video);
        for row in [
            s.splits.entry(split.clone()).or_default(),
            s.scenarios
                .entry(scen)
                .or_default()
                .entry(split.clone())
                .or_default(),
        ] {
            row.frames += 1;
            row.objects += f.objects.len() as u64;
            row.empty_frames += u64::from(f.objects.is_empty());
        }
        *s.objects_per_frame.entry(f.objects.len()).or_default() += 1;
        for o in &f.objects {
            let name = ds
                .classes
                .get(usize::from(o.class))
                .map(|c| c.name.clone())
                .unwrap_or_else(|| format!("class {}", o.class));
            *s.classes
                .entry(name)
                .or_default()
                .entry(split.clone())
                .or_default() += 1;
            sizes.push(o.bbox.area().sqrt());
            widths.push(o.bbox.width());
            heights.push(o.bbox.height());
        }
    }
    s.box_size = SizeStats::of(sizes);
    s.box_width = SizeStats::of(widths);
    s.box_height = SizeStats::of(heights);
    s
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let splits: Vec<&str> = Split::ALL.iter().map(|s| s.name()).collect();
        writeln!(
            f,
            "{:<22} {:>7} {:>8} {:>8} {:>8}",
            "split", "videos", "frames", "empty", "objects"
        )?;
        let mut total = Row::default();
        for sp in &splits {
            let r = self.splits.get(*sp).copied().unwrap_or_default();
            writeln!(
                f,
                "{:<22} {:>7} {:>8} {:>8} {:>8}",
                sp, r.videos, r.frames, r.empty_frames, r.objects
            )?;
            total.videos += r.videos;
            total.frames += r.frames;
            total.empty_frames += r.empty_frames;
            total.objects += r.objects;
        }
        writeln!(
            f,
            "{:<22} {:>7} {:>8} {:>8} {:>8}",
            "total", total.videos, total.frames, total.empty_frames, total.objects
        )?;
        writeln!(f)?;
        writeln!(f, "scenario: videos/frames/objects per split")?;
        writeln!(
            f,
            "{:<22} {:>20} {:>20} {:>20}",
            "clutter/light", "train", "val", "test"
        )?;
        for (scen, rows) in &self.scenarios {
            write!(f, "{scen:<22}")?;
            for sp in &splits {
                let r = rows.get(*sp).copied().unwrap_or_default();
                write!(
                    f,
                    " {:>20}",
                    format!("{}/{}/{}", r.videos, r.frames, r.objects)
                )?;
            }
            writeln!(f)?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "{:<22} {:>8} {:>8} {:>8}",
            "class (objects)", "train", "val", "test"
        )?;
        for (name, per) in &self.classes {
            write!(f, "{name:<22}")?;
            for sp in &splits {
                write!(f, " {:>8}", per.get(*sp).copied().unwrap_or(0))?;
            }
            writeln!(f)?;
        }
        writeln!(f)?;
        for (label, s) in [
            ("box size sqrt(wh)", self.box_size),
            ("box width", self.box_width),
            ("box height", self.box_height),
        ] {
            writeln!(
                f,
                "{label:<22} min {:.1}  median {:.1}  mean {:.1}  max {:.1} px",
                s.min, s.median, s.mean, s.max
            )?;
        }
        let per: Vec<String> = self
            .objects_per_frame
            .iter()
            .map(|(k, v)| format!("{k}: {v}"))
            .collect();
        writeln!(f, "{:<22} {}", "objects per frame", per.join(", "))
    }
}
