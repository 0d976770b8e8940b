//! The configuration of `frugal run`: one section per stage, each the stage's own
//! config type, on top of a built-in profile (`default`, `quick`, `tiny`).
//!
//! A config file (TOML or JSON) names a `profile` (default: `default`) and overrides
//! any subset of its values; tables merge key by key, lists and tagged values (tables
//! with a `kind` or `method` key) replace the profile's whole. Everything is checked
//! before any work starts: an unknown key is named with its path and the keys allowed
//! there, a value out of range with its section, a maze that does not exist by name.
//!
//! Over 600 lines with its unit tests (the last 175).
use anyhow::{Context, bail};
use clap::ValueEnum;
use frugal_data::GenConfig;
use frugal_models::compress::Grid;
use frugal_models::config::Config as DetectorConfig;
use frugal_policies::PolicyConfig;
use frugal_policies::budget::BudgetConfig;
use frugal_policies::eval::EvalConfig;
use frugal_runtime::pilot::Carry;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// A built-in starting point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Profile {
    /// The real configuration: the README's figures come from it (≤ 30 min on 2 cores).
    Default,
    /// A first look in a few minutes: small frames, a small model, few variants.
    Quick,
    /// Seconds: what the end-to-end tests run.
    Tiny,
}

/// `frugal pareto` settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParetoSettings {
    /// ONNX Runtime intra-op threads, the same for every variant.
    pub threads: usize,
    /// Validation frames scored per variant, spread evenly (0 = all).
    pub frames: usize,
    /// Of those, the frames timed, spread evenly (0 = all); the others are scored for
    /// accuracy only, on every core.
    pub timed_frames: usize,
    /// Untimed warm-up detections per variant.
    pub warmup: usize,
    /// Score threshold of precision / recall / F1 and IoU.
    pub threshold: f32,
}

/// `frugal policy record` settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplaySettings {
    /// Videos per (split, clutter, light) replayed (0 = all); the MDP is estimated on
    /// the training videos and the strategies are compared on the test videos.
    pub per_combo: usize,
    /// ONNX Runtime threads per variant.
    pub threads: usize,
    /// Detections kept per frame and variant.
    pub max_detections: usize,
    /// The dataset split the policy learns from (`val`: videos the detector was not
    /// trained on; `train` biases every variant's statistics upwards).
    pub train_split: String,
    /// Give every variant its own buckets of equal precision (`frugal policy calibrate`).
    pub calibrate: bool,
    /// Frames that must back a calibrated bucket edge.
    pub calibrate_min_samples: usize,
    /// Flight footage the policy also learns from (none by default).
    #[serde(default)]
    pub footage: Option<FootageSettings>,
}

/// Flight footage for the policy (`frugal fly --record`, then `frugal policy record`
/// on it): ground-truth flights through training mazes, whose frames every variant of
/// the front replays; `frugal policy train --extra-log` adds them to the policy's
/// training videos.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FootageSettings {
    /// Training maze names (`train-a`, `train-b`, `train-c`) or maze files; never an
    /// evaluation maze of `[flights]`.
    pub mazes: Vec<String>,
    /// Flights per maze.
    pub seeds: u64,
    /// Keep one processed frame in this many.
    pub every: u64,
}

/// `frugal fly` settings: static (the most accurate variant) against adaptive (the
/// bundle), on the same mazes, seeds and device profile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlightSettings {
    /// Shipped maze names (`easy`, `medium`, `hard`) or maze files.
    pub mazes: Vec<String>,
    /// Flights per maze and perception.
    pub seeds: u64,
    /// First seed.
    pub seed: u64,
    /// Device profile (`host` or `tx2-like`).
    pub device: String,
    /// Camera size, pixels.
    pub width: u32,
    /// Camera height, pixels.
    pub height: u32,
    /// Simulated time limit per flight, seconds.
    pub time_limit_s: f64,
    /// ONNX Runtime threads.
    pub threads: usize,
    /// Save the first adaptive flight of each maze as a GIF.
    pub gif: bool,
    /// Which detections the adaptive runtime carries with its trackers (`frugal fly
    /// --carry`): `"optimal"` (the default profile's, as its replay evaluation),
    /// `"good-enough"` or `"reported"` (the paper's rule; the flight config's).
    pub carry: Carry,
}

/// The whole pipeline's configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// The profile the values started from.
    pub profile: Profile,
    /// `frugal data generate`.
    pub data: GenConfig,
    /// `frugal data import`: real footage instead of the synthetic videos. With it the
    /// data stage imports, the budget stage scores the imported test part only (no
    /// synthetic held-out videos), and maze flights run only when the classes are the
    /// synthetic signs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub import: Option<frugal_data::ImportSettings>,
    /// `frugal train` (model structure and training).
    pub detector: DetectorConfig,
    /// `frugal compress` (the variant grid).
    pub compress: Grid,
    /// `frugal pareto`.
    pub pareto: ParetoSettings,
    /// `frugal policy record`.
    pub replay: ReplaySettings,
    /// `frugal policy train`.
    pub policy: PolicyConfig,
    /// `frugal policy eval` (its thresholds go into the bundle too).
    pub evaluation: EvalConfig,
    /// `frugal policy budget`: the budget + content policy, its latency budgets, and
    /// the streaming evaluation of every budget strategy.
    pub budget: BudgetConfig,
    /// Videos of a seed (and scenario mix) no other stage sees, generated by the budget
    /// stage: the out-of-sample check of every policy.
    pub heldout: GenConfig,
    /// Videos of a seed of their own, generated by the budget stage, on which the
    /// budget tables are chosen (with the replay's training videos) and never scored.
    pub tuning: GenConfig,
    /// `frugal fly`.
    pub flights: FlightSettings,
}

/// The variant grid of the quick profile: the base model, int8, channel pruning and
/// layer removal, so the policy still has a spread of costs to choose from.
const QUICK_GRID: &str = r#"
calibration_frames = 8
drift_frames = 4
[finetune]
steps = 40
frames = 36
[[variants]]
name = "base"
technique = { kind = "base" }
[[variants]]
name = "base-int8"
parent = "base"
technique = { kind = "int8" }
[[variants]]
name = "ch50"
technique = { kind = "channels", keep = 0.5 }
[[variants]]
name = "ch50-int8"
parent = "ch50"
technique = { kind = "int8" }
[[variants]]
name = "res050"
technique = { kind = "resolution", scale = 0.5 }
"#;

/// The tiny profile's grid: three variants, two fine-tuning steps.
const TINY_GRID: &str = r#"
calibration_frames = 3
drift_frames = 2
[finetune]
steps = 2
frames = 6
[[variants]]
name = "base"
technique = { kind = "base" }
[[variants]]
name = "base-int8"
parent = "base"
technique = { kind = "int8", calibration = { method = "min_max" } }
[[variants]]
name = "ch50"
technique = { kind = "channels", keep = 0.5 }
"#;

/// The tiny profile's detector (TOML): a few thousand parameters, two short epochs;
/// the end-to-end tests train it too.
pub const TINY_DETECTOR: &str = r#"
[model]
backbone = [
  { out_channels = 8, stride = 2, convs = 1 },
  { out_channels = 16, stride = 2, convs = 1 },
  { out_channels = 16, stride = 1, convs = 1 },
]
rpn_channels = 8
anchor_sizes = [12.0, 24.0]
anchor_ratios = [1.0]
roi_size = 3
roi_hidden = 16
pre_nms_train = 100
post_nms_train = 30
pre_nms_test = 100
post_nms_test = 10
[train]
epochs = 2
batch_size = 3
warmup_steps = 1
train_frames = 6
val_frames = 2
val_every = 2
threads = 1
"#;

/// The quick profile's detector: half the default widths, 320×180 frames.
const QUICK_DETECTOR: &str = r#"
[model]
backbone = [
  { out_channels = 16, stride = 2, convs = 1 },
  { out_channels = 32, stride = 2, convs = 1 },
  { out_channels = 64, stride = 2, convs = 1 },
  { out_channels = 128, stride = 1, convs = 1 },
]
rpn_channels = 32
roi_hidden = 128
[train]
epochs = 12
batch_size = 4
warmup_steps = 20
val_frames = 60
threads = 2
"#;

impl RunConfig {
    /// The built-in values of a profile.
    pub fn profile(profile: Profile) -> anyhow::Result<RunConfig> {
        let parse_grid = |text: &str| toml::from_str::<Grid>(text).context("built-in grid");
        let parse_detector =
            |text: &str| toml::from_str::<DetectorConfig>(text).context("built-in detector");
        let mut detector = DetectorConfig::default();
        // both cores of the 2-core budget (the tests' tiny profile uses one)
        detector.train.threads = 2;
        // validation after epochs 2, 4, 6 and 8: the best epoch is a late one, and each
        // pass over the 300 validation frames costs about 7 s
        detector.train.val_every = 2;
        let replay = ReplaySettings {
            per_combo: 0,
            threads: 1,
            max_detections: frugal_policies::replay::DEFAULT_MAX_DETECTIONS,
            train_split: "val".into(),
            calibrate: true,
            calibrate_min_samples: 20,
            footage: None,
        };
        let default_flights = FlightSettings {
            mazes: vec!["easy".into(), "medium".into(), "hard".into()],
            seeds: 2,
            seed: 1,
            device: "tx2-like".into(),
            width: 480,
            height: 270,
            time_limit_s: 900.0,
            threads: 1,
            gif: true,
            carry: Carry::Optimal,
        };
        Ok(match profile {
            Profile::Default => RunConfig {
                profile,
                data: GenConfig::default(),
                import: None,
                detector,
                compress: Grid::default(),
                pareto: ParetoSettings {
                    threads: 1,
                    frames: 0,
                    timed_frames: 180,
                    warmup: 3,
                    threshold: 0.5,
                },
                replay: replay.clone(),
                policy: PolicyConfig::default(),
                evaluation: EvalConfig::default(),
                budget: BudgetConfig::default(),
                // workbench/configs/heldout.toml's values: seed 2031, medium and high
                // clutter, normal and low light, 24 test videos, smaller and faster signs
                heldout: GenConfig {
                    seed: 2031,
                    clutter: vec![frugal_data::Clutter::Medium, frugal_data::Clutter::High],
                    videos_per_combo: 8,
                    val_per_combo: 1,
                    test_per_combo: 6,
                    frames_per_video: 60,
                    train_frames_per_video: 6,
                    min_sign_px: 12.0,
                    max_motion_blur_px: 5.0,
                    ..GenConfig::default()
                },
                // the training data's scenario mix, seed 2029: 48 videos of 60 frames
                tuning: GenConfig {
                    seed: 2029,
                    videos_per_combo: 10,
                    val_per_combo: 0,
                    test_per_combo: 8,
                    frames_per_video: 60,
                    train_frames_per_video: 6,
                    ..GenConfig::default()
                },
                flights: default_flights,
            },
            Profile::Quick => RunConfig {
                profile,
                import: None,
                // short training clips as in the default, at 320×180
                data: GenConfig {
                    videos_per_combo: 24,
                    val_per_combo: 1,
                    test_per_combo: 1,
                    frames_per_video: 30,
                    train_frames_per_video: 6,
                    ..GenConfig::quick()
                },
                detector: parse_detector(QUICK_DETECTOR)?,
                compress: parse_grid(QUICK_GRID)?,
                pareto: ParetoSettings {
                    threads: 1,
                    frames: 0,
                    timed_frames: 120,
                    warmup: 2,
                    threshold: 0.5,
                },
                replay: replay.clone(),
                policy: PolicyConfig::default(),
                evaluation: EvalConfig::default(),
                budget: BudgetConfig::default(),
                heldout: GenConfig {
                    seed: 2031,
                    frames_per_video: 30,
                    ..GenConfig::quick()
                },
                tuning: GenConfig {
                    seed: 2029,
                    frames_per_video: 30,
                    ..GenConfig::quick()
                },
                flights: FlightSettings {
                    mazes: vec!["easy".into()],
                    seeds: 1,
                    width: 320,
                    height: 180,
                    time_limit_s: 300.0,
                    gif: false,
                    ..default_flights
                },
            },
            Profile::Tiny => RunConfig {
                profile,
                data: GenConfig::tiny(),
                import: None,
                detector: parse_detector(TINY_DETECTOR)?,
                compress: parse_grid(TINY_GRID)?,
                pareto: ParetoSettings {
                    threads: 1,
                    frames: 0,
                    // two of them: the untimed frames run on the other workers
                    timed_frames: 2,
                    warmup: 1,
                    threshold: 0.5,
                },
                replay: ReplaySettings {
                    calibrate_min_samples: 2,
                    ..replay
                },
                policy: PolicyConfig {
                    sweep_alpha: vec![0.0, 1.0],
                    sweep_ge_scale: vec![1.0],
                    ..PolicyConfig::default()
                },
                evaluation: EvalConfig::default(),
                budget: BudgetConfig {
                    clock_runs: 2,
                    ..BudgetConfig::default()
                },
                heldout: GenConfig {
                    seed: 2031,
                    ..GenConfig::tiny()
                },
                tuning: GenConfig {
                    seed: 2029,
                    ..GenConfig::tiny()
                },
                flights: FlightSettings {
                    mazes: vec!["easy".into()],
                    seeds: 1,
                    device: "tx2-like".into(),
                    width: 160,
                    height: 90,
                    time_limit_s: 4.0,
                    gif: false,
                    ..default_flights
                },
            },
        })
    }

    /// Read a config file over its profile (`profile` key, else `fallback`), then
    /// check every value. Nothing is written.
    pub fn load(path: Option<&Path>, fallback: Profile) -> anyhow::Result<RunConfig> {
        let Some(path) = path else {
            let cfg = RunConfig::profile(fallback)?;
            cfg.check(Path::new("<built-in>"))?;
            return Ok(cfg);
        };
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the run config", path.display()))?;
        let user: Value = if path.extension().is_some_and(|e| e == "toml") {
            toml::from_str(&text).with_context(|| format!("{}: invalid TOML", path.display()))?
        } else {
            serde_json::from_str(&text)
                .with_context(|| format!("{}: invalid JSON", path.display()))?
        };
        let Value::Object(map) = &user else {
            bail!("{}: the run config must be a table", path.display());
        };
        let profile = match map.get("profile") {
            None => fallback,
            Some(v) => serde_json::from_value(v.clone()).map_err(|_| {
                anyhow::anyhow!(
                    "{}: profile: {v} is not a profile (allowed: default, quick, tiny)",
                    path.display()
                )
            })?,
        };
        let mut merged = serde_json::to_value(RunConfig::profile(profile)?)?;
        // keys no profile's JSON form holds, which a config file may set: present, as
        // unset (a generator leaves an unset pace out, so its hash stays the same)
        let paces =
            ["/data", "/heldout", "/tuning"].map(|set| (set, "pace_frames", Value::from(0u32)));
        let unset = [
            ("", "import", Value::Null),
            ("/detector/model", "input_size", Value::Null),
        ]
        .into_iter()
        .chain(paces);
        for (parent, key, value) in unset {
            if let Some(Value::Object(m)) = merged.pointer_mut(parent) {
                m.entry(key).or_insert(value);
            }
        }
        merge(&mut merged, &user, "").with_context(|| path.display().to_string())?;
        let cfg = from_sections(&merged).with_context(|| path.display().to_string())?;
        cfg.check(path)?;
        Ok(cfg)
    }

    /// Range checks of every section; `path` names the file in errors.
    pub fn check(&self, path: &Path) -> anyhow::Result<()> {
        let file = path.display().to_string();
        self.data.validate(path).context("in section [data]")?;
        self.detector
            .validate(&format!("{file} [detector]"))
            .map_err(anyhow::Error::from)?;
        self.compress
            .validate(&format!("{file} [compress]"))
            .map_err(anyhow::Error::from)?;
        self.policy.check(path).context("in section [policy]")?;
        let bad = |key: &str, msg: String| anyhow::anyhow!("{file}: {key}: {msg}");
        let p = &self.pareto;
        if p.threads == 0 {
            return Err(bad("pareto.threads", "must be at least 1".into()));
        }
        if !(0.0..=1.0).contains(&p.threshold) {
            return Err(bad(
                "pareto.threshold",
                format!("{} is outside [0, 1]", p.threshold),
            ));
        }
        if !matches!(self.replay.train_split.as_str(), "train" | "val") {
            return Err(bad(
                "replay.train_split",
                format!(
                    "`{}` is not allowed (allowed: train, val)",
                    self.replay.train_split
                ),
            ));
        }
        if self.replay.threads == 0 || self.replay.max_detections == 0 {
            return Err(bad(
                "replay.threads / replay.max_detections",
                "must be at least 1".into(),
            ));
        }
        if let Some(f) = &self.replay.footage {
            if f.mazes.is_empty() || f.seeds == 0 || f.every == 0 {
                return Err(bad(
                    "replay.footage",
                    "needs at least one maze, one seed, and every >= 1".into(),
                ));
            }
            let flown: Vec<String> = self
                .flights
                .mazes
                .iter()
                .filter_map(|m| frugal_sim::Maze::resolve(Path::new(m)).ok())
                .map(|m| m.name)
                .collect();
            for m in &f.mazes {
                let maze = frugal_sim::Maze::resolve(Path::new(m)).map_err(|e| {
                    bad(
                        "replay.footage.mazes",
                        format!("{e} (training mazes: train-a, train-b, train-c)"),
                    )
                })?;
                if flown.contains(&maze.name) {
                    return Err(bad(
                        "replay.footage.mazes",
                        format!(
                            "`{m}` is flown in [flights]: the policy must not learn from an evaluation maze"
                        ),
                    ));
                }
            }
        }
        let e = &self.evaluation;
        if !(0.0..=1.0).contains(&e.iou_threshold) || !(0.0..=1.0).contains(&e.eval_iou) {
            return Err(bad(
                "evaluation.iou_threshold / evaluation.eval_iou",
                "must lie in [0, 1]".into(),
            ));
        }
        if e.mdp_period == 0 || e.reinit_period == 0 || e.max_tracks == 0 {
            return Err(bad(
                "evaluation.mdp_period / reinit_period / max_tracks",
                "must be at least 1".into(),
            ));
        }
        let most = frugal_runtime::bundle::MAX_ACCESSES;
        if !(1..=most).contains(&e.accesses_per_image) {
            return Err(bad(
                "evaluation.accesses_per_image",
                format!("must lie in 1..={most} (paper: 5; 1 turns it off)"),
            ));
        }
        self.budget.check(path).context("in section [budget]")?;
        if let Some(i) = &self.import {
            i.options().context("in section [import]")?;
        }
        // the held-out videos and the tuning videos: generated unless footage is
        // imported (then the imported test part is the held-out set, and the tables
        // are chosen on the training part alone)
        let d = &self.data;
        for (name, g) in [("heldout", &self.heldout), ("tuning", &self.tuning)] {
            g.validate(path)
                .with_context(|| format!("in section [{name}]"))?;
            if self.import.is_some() {
                continue;
            }
            if g.seed == d.seed {
                return Err(bad(
                    &format!("{name}.seed"),
                    format!(
                        "{} is [data]'s seed: the {name} videos need a seed of their own",
                        g.seed
                    ),
                ));
            }
            if (g.width, g.height) != (d.width, d.height) {
                return Err(bad(
                    &format!("{name}.width / {name}.height"),
                    format!(
                        "{}×{} differs from [data]'s {}×{} (the variants' input)",
                        g.width, g.height, d.width, d.height
                    ),
                ));
            }
        }
        if self.import.is_none() && self.tuning.seed == self.heldout.seed {
            return Err(bad(
                "tuning.seed",
                format!(
                    "{} is [heldout]'s seed: the tables would be chosen on the videos that judge them",
                    self.tuning.seed
                ),
            ));
        }
        let f = &self.flights;
        if f.mazes.is_empty() {
            return Err(bad("flights.mazes", "name at least one maze".into()));
        }
        for m in &f.mazes {
            frugal_sim::Maze::resolve(Path::new(m)).map_err(|e| {
                bad(
                    "flights.mazes",
                    format!("{e} (shipped mazes: easy, medium, hard)"),
                )
            })?;
        }
        if f.seeds == 0 {
            return Err(bad("flights.seeds", "must be at least 1".into()));
        }
        if frugal_sim::DeviceProfile::by_name(&f.device).is_none() {
            return Err(bad(
                "flights.device",
                format!(
                    "`{}` is not a device profile (allowed: host, tx2-like)",
                    f.device
                ),
            ));
        }
        if f.width < 32 || f.height < 18 {
            return Err(bad(
                "flights.width / flights.height",
                "the camera needs at least 32×18 pixels".into(),
            ));
        }
        if !(f.time_limit_s > 0.0 && f.time_limit_s.is_finite()) {
            return Err(bad("flights.time_limit_s", "must be positive".into()));
        }
        if f.threads == 0 {
            return Err(bad("flights.threads", "must be at least 1".into()));
        }
        Ok(())
    }

    /// Maze arguments for `frugal fly`: a file path when one exists, else the name.
    pub fn maze_args(&self) -> Vec<PathBuf> {
        self.flights.mazes.iter().map(PathBuf::from).collect()
    }
}

/// Deserialize section by section, so a wrong type names its section.
fn from_sections(v: &Value) -> anyhow::Result<RunConfig> {
    fn section<T: serde::de::DeserializeOwned>(v: &Value, key: &str) -> anyhow::Result<T> {
        serde_json::from_value(v.get(key).cloned().unwrap_or(Value::Null))
            .with_context(|| format!("[{key}]"))
    }
    Ok(RunConfig {
        profile: section(v, "profile")?,
        data: section(v, "data")?,
        import: section(v, "import")?,
        detector: section(v, "detector")?,
        compress: section(v, "compress")?,
        pareto: section(v, "pareto")?,
        replay: section(v, "replay")?,
        policy: section(v, "policy")?,
        evaluation: section(v, "evaluation")?,
        budget: section(v, "budget")?,
        heldout: section(v, "heldout")?,
        tuning: section(v, "tuning")?,
        flights: section(v, "flights")?,
    })
}

/// Overlay `user` on `base`: tables merge key by key (a key the base lacks is an
/// error naming its path and the allowed keys); lists, scalars and tagged tables
/// replace the base value.
fn merge(base: &mut Value, user: &Value, path: &str) -> anyhow::Result<()> {
    const TAGS: [&str; 2] = ["kind", "method"];
    match (base, user) {
        (Value::Object(b), Value::Object(u)) if !TAGS.iter().any(|t| u.contains_key(*t)) => {
            for (k, uv) in u {
                let here = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                match b.get_mut(k) {
                    Some(bv) => merge(bv, uv, &here)?,
                    None => {
                        let mut allowed: Vec<&str> = b.keys().map(String::as_str).collect();
                        allowed.sort_unstable();
                        bail!(
                            "unknown key `{here}` (allowed here: {})",
                            allowed.join(", ")
                        );
                    }
                }
            }
            Ok(())
        }
        (b, u) => {
            *b = u.clone();
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> anyhow::Result<RunConfig> {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("run.toml");
        std::fs::write(&path, text)?;
        RunConfig::load(Some(&path), Profile::Default).map_err(|e| anyhow::anyhow!("{e:#}"))
    }

    /// The error `load` gives for `text`, as a string.
    fn load_err(text: &str) -> String {
        load(text).unwrap_err().to_string()
    }

    #[test]
    fn every_profile_is_valid() {
        for p in [Profile::Default, Profile::Quick, Profile::Tiny] {
            let cfg = RunConfig::profile(p).unwrap();
            cfg.check(Path::new("<built-in>")).unwrap();
            assert_eq!(cfg.profile, p);
        }
    }

    #[test]
    fn a_file_overrides_its_profile_key_by_key() {
        let cfg = load(
            "profile = \"quick\"\n[detector.train]\nepochs = 7\n[flights]\nmazes = [\"hard\"]\n",
        )
        .unwrap();
        let quick = RunConfig::profile(Profile::Quick).unwrap();
        assert_eq!(cfg.detector.train.epochs, 7);
        // untouched keys keep the quick profile's values, not the types' defaults
        assert_eq!(cfg.detector.model, quick.detector.model);
        assert_eq!(
            cfg.detector.train.batch_size,
            quick.detector.train.batch_size
        );
        assert_eq!(cfg.data, quick.data);
        assert_eq!(cfg.flights.mazes, vec!["hard".to_string()]);
        assert_eq!(cfg.flights.width, quick.flights.width);
    }

    /// `pace_frames` is left out of a generator config's JSON form when unset, so no
    /// profile carries it; a run config may still set it in every generated set.
    #[test]
    fn a_run_config_may_pace_its_generated_videos() {
        let cfg = load(
            "[tuning]\nframes_per_video = 240\npace_frames = 60\n\
             [heldout]\nframes_per_video = 240\npace_frames = 80\n\
             [data]\npace_frames = 30\n",
        )
        .unwrap();
        assert_eq!(
            (
                cfg.tuning.pace_frames,
                cfg.heldout.pace_frames,
                cfg.data.pace_frames
            ),
            (60, 80, 30)
        );
        assert_eq!(cfg.tuning.frames_per_video, 240);
        let unset = load("[tuning]\nframes_per_video = 240\n").unwrap();
        assert_eq!(
            (
                unset.tuning.pace_frames,
                unset.heldout.pace_frames,
                unset.data.pace_frames
            ),
            (0, 0, 0)
        );
        // still unknown where no generator reads it
        let e = load_err("[budget]\npace_frames = 60\n");
        assert!(e.contains("budget.pace_frames"), "{e}");
    }

    #[test]
    fn bad_configs_name_the_key_and_what_is_allowed() {
        let e = load_err("[detector.train]\nepochz = 3\n");
        assert!(
            e.contains("detector.train.epochz") && e.contains("epochs") && e.contains("run.toml"),
            "{e}"
        );
        let e = load_err("[polcy]\nalpha = 1\n");
        assert!(e.contains("`polcy`") && e.contains("policy"), "{e}");
        let e = load_err("profile = \"huge\"\n");
        assert!(e.contains("huge") && e.contains("quick"), "{e}");
        let e = load_err("[policy]\ngamma = 1.5\n");
        assert!(e.contains("gamma") && e.contains("[0, 1)"), "{e}");
        let e = load_err("[budget]\nburst = 0.5\n");
        assert!(
            e.contains("[budget]") && e.contains("burst") && e.contains(">= 1"),
            "{e}"
        );
        let e = load_err("[flights]\nmazes = [\"nowhere.maze\"]\n");
        assert!(
            e.contains("flights.mazes") && e.contains("nowhere.maze"),
            "{e}"
        );
        let e = load_err("[flights]\ndevice = \"jetson\"\n");
        assert!(
            e.contains("flights.device") && e.contains("tx2-like"),
            "{e}"
        );
        let e = load_err("[flights]\ncarry = \"everything\"\n");
        assert!(e.contains("everything") && e.contains("reported"), "{e}");
        let e = load_err("[pareto]\nthreads = \"two\"\n");
        assert!(e.contains("[pareto]"), "{e}");
        let e = load_err("[data]\nwidth = 0\n");
        assert!(
            e.contains("[data]") && e.contains("frame size 0x270"),
            "{e}"
        );
        // the tables must not be chosen on the videos that judge them, nor on the
        // training data's seed
        let e = load_err("[tuning]\nseed = 2031\n");
        assert!(
            e.contains("tuning.seed") && e.contains("[heldout]'s seed"),
            "{e}"
        );
        let e = load_err("[tuning]\nseed = 2026\n");
        assert!(
            e.contains("tuning.seed") && e.contains("[data]'s seed"),
            "{e}"
        );
        let e = load_err("[tuning]\nwidth = 320\nheight = 180\n");
        assert!(e.contains("tuning.width") && e.contains("480×270"), "{e}");
    }

    #[test]
    fn the_shipped_flight_config_shares_the_default_data_and_detector_and_adds_cheap_variants_and_footage()
     {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/flight.toml");
        let cfg = RunConfig::load(Some(&path), Profile::Default).unwrap();
        cfg.check(&path).unwrap();
        let default = RunConfig::profile(Profile::Default).unwrap();
        // the data and detector stages hash the same sections, so a default run's
        // folders are reused
        assert_eq!(cfg.data, default.data);
        assert_eq!(cfg.detector, default.detector);
        assert_eq!(
            EvalConfig {
                accesses_per_image: default.evaluation.accesses_per_image,
                ..cfg.evaluation.clone()
            },
            default.evaluation
        );
        assert_eq!(cfg.evaluation.accesses_per_image, 1);
        // the policy differs in what it pays for: cost (α), far signs (don't-care
        // below 24 px), and flight footage from the training mazes only
        assert_eq!(
            PolicyConfig {
                alpha: default.policy.alpha,
                outcome_min_px: default.policy.outcome_min_px,
                ..cfg.policy.clone()
            },
            default.policy
        );
        assert_eq!((cfg.policy.alpha, cfg.policy.outcome_min_px), (0.2, 24.0));
        // its flights carry every reported detection (the paper's rule); the default
        // profile's carry from the optimal bucket, as its replay evaluation
        assert_eq!(cfg.flights.carry, Carry::Reported);
        assert_eq!(default.flights.carry, Carry::Optimal);
        let footage = cfg.replay.footage.clone().unwrap();
        assert_eq!(footage.mazes, ["train-a", "train-b", "train-c"]);
        assert!(footage.mazes.iter().all(|m| !cfg.flights.mazes.contains(m)));
        let names = |g: &Grid| {
            g.variants
                .iter()
                .map(|v| v.name.clone())
                .collect::<Vec<_>>()
        };
        let (ours, theirs) = (names(&cfg.compress), names(&default.compress));
        assert!(theirs.iter().all(|n| ours.contains(n)), "{ours:?}");
        for cheap in ["ch50-p20-int8", "ch25-p20-int8"] {
            assert!(ours.contains(&cheap.to_string()), "{ours:?}");
        }
        let ch50 = cfg
            .compress
            .variants
            .iter()
            .find(|v| v.name == "ch50")
            .unwrap();
        assert_eq!((ch50.steps, cfg.compress.finetune.frames), (Some(1000), 0));
    }

    #[test]
    fn the_shipped_slow_flight_config_changes_only_the_videos_the_budget_tables_meet() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/slow-flight.toml");
        let cfg = RunConfig::load(Some(&path), Profile::Default).unwrap();
        let default = RunConfig::profile(Profile::Default).unwrap();
        // every stage before the budget stage hashes the same sections, so a copied
        // default run skips them
        assert_eq!(cfg.data, default.data);
        assert_eq!(cfg.detector, default.detector);
        assert_eq!(cfg.compress, default.compress);
        assert_eq!(cfg.pareto, default.pareto);
        assert_eq!(cfg.replay, default.replay);
        assert_eq!(cfg.policy, default.policy);
        assert_eq!(cfg.evaluation, default.evaluation);
        assert_eq!(cfg.budget, default.budget);
        assert_eq!(cfg.flights, default.flights);
        // long, unpaced videos of the same mixes (a slower flight), new seeds
        for (set, was) in [
            (&cfg.tuning, &default.tuning),
            (&cfg.heldout, &default.heldout),
        ] {
            assert_eq!(set.frames_per_video, 4 * was.frames_per_video);
            assert_eq!(set.pace_frames, 0);
            assert_eq!((&set.clutter, &set.light), (&was.clutter, &was.light));
            assert_eq!(set.min_sign_px, was.min_sign_px);
            let tests = set.clutter.len() * set.light.len() * set.test_per_combo as usize;
            assert_eq!(tests, 24);
        }
        // seeds of their own: neither the training data's nor the default run's sets
        let seeds = [cfg.tuning.seed, cfg.heldout.seed];
        for s in seeds {
            assert!(![cfg.data.seed, default.tuning.seed, default.heldout.seed].contains(&s));
        }
        assert_ne!(seeds[0], seeds[1]);
    }

    #[test]
    fn footage_comes_from_training_mazes_only_and_is_off_by_default() {
        let default = RunConfig::profile(Profile::Default).unwrap();
        assert_eq!(default.replay.footage, None);
        let cfg =
            load("[replay.footage]\nmazes = [\"train-a\", \"train-c\"]\nseeds = 2\nevery = 3\n")
                .unwrap();
        let f = cfg.replay.footage.unwrap();
        assert_eq!((f.mazes.len(), f.seeds, f.every), (2, 2, 3));
        let e = load_err("[replay.footage]\nmazes = [\"hard\"]\nseeds = 1\nevery = 3\n");
        assert!(
            e.contains("replay.footage.mazes") && e.contains("evaluation maze"),
            "{e}"
        );
        let e = load_err("[replay.footage]\nmazes = [\"nowhere\"]\nseeds = 1\nevery = 3\n");
        assert!(e.contains("nowhere") && e.contains("train-a"), "{e}");
        let e = load_err("[replay.footage]\nmazes = [\"train-a\"]\nseeds = 1\nevery = 0\n");
        assert!(e.contains("replay.footage"), "{e}");
    }

    #[test]
    fn tagged_values_replace_rather_than_merge() {
        let cfg = load("[compress]\ncalibration = { method = \"min_max\" }\n").unwrap();
        assert_eq!(
            serde_json::to_value(cfg.compress.calibration).unwrap(),
            serde_json::json!({ "method": "min_max" })
        );
    }
}
