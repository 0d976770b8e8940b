//! The stages of `frugal run`, their inputs hash, and the partial-folder / stamp /
//! rename protocol that makes a killed run restartable.
//!
//! Long because it holds the ten stages' command lines (`Ctx::exec`) next to the
//! protocol that runs, stamps and skips them; a stage's inputs hash and its commands
//! must change together.
use super::RunArgs;
use super::config::{FootageSettings, RunConfig};
use anyhow::{Context, bail};
use frugal_data::dataset::write_atomic;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// One stage: its folder name under the run, the stages whose output it reads, and
/// what it makes (for the progress lines and the report).
#[derive(Clone, Copy, Debug)]
pub(crate) struct StageDef {
    /// Folder name and `--force` / `--until` value.
    pub name: &'static str,
    /// Upstream stages.
    pub deps: &'static [&'static str],
    /// One line on what it makes.
    pub what: &'static str,
}

/// The pipeline, in order.
pub(crate) const STAGES: [StageDef; 10] = [
    StageDef {
        name: "data",
        deps: &[],
        what: "the dataset (synthetic videos with exact boxes, or imported footage), and a contact sheet",
    },
    StageDef {
        name: "detector",
        deps: &["data"],
        what: "the CNN detector, trained, and scored on the held-out test videos",
    },
    StageDef {
        name: "variants",
        deps: &["detector", "data"],
        what: "compressed variants (int8, pruning, layer removal, resolution) as ONNX",
    },
    StageDef {
        name: "pareto",
        deps: &["variants", "data"],
        what: "accuracy and ONNX Runtime latency of every variant, the Pareto front",
    },
    StageDef {
        name: "replay",
        deps: &["pareto", "data"],
        what: "every front variant on every frame of the policy's training videos (by default the validation split) and the test videos, calibrated",
    },
    StageDef {
        name: "policy",
        deps: &["replay"],
        what: "the MDP, solved by value iteration, and the α sweep",
    },
    StageDef {
        name: "evaluation",
        deps: &["replay", "policy"],
        what: "static, random, MDP, with and without tracker, and the oracle, on test videos",
    },
    StageDef {
        name: "budget",
        deps: &["replay", "policy", "pareto"],
        what: "the budget + content policy, and every strategy streamed on a simulated clock (streaming AP) on the test videos and (synthetic data) on held-out videos of a new seed",
    },
    StageDef {
        name: "bundle",
        deps: &["budget"],
        what: "the policy bundle the drone loads, verified",
    },
    StageDef {
        name: "flights",
        deps: &["bundle", "budget", "evaluation", "pareto"],
        what: "closed-loop maze flights, static detector against the adaptive runtime (when the classes are the synthetic signs)",
    },
];

/// The replay log of the flight footage, in the replay stage's folder.
pub(crate) const FOOTAGE_LOG: &str = "footage.json";

/// Bumped when a stage's commands change in a way that changes its output.
const PIPELINE_VERSION: u32 = 1;

/// What a completed stage leaves in `<run>/<stage>/.stamp.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Stamp {
    /// Stage name.
    pub stage: String,
    /// Hash of the config section, the upstream outputs and frugal's version.
    pub inputs_hash: String,
    /// Content hash of the stage's files (what downstream stages hash).
    pub output_hash: String,
    /// The commands that made the output (as `frugal …` lines).
    pub commands: Vec<String>,
    /// The config file the commands read, relative to the run folder, if any.
    pub config_file: Option<String>,
    /// Wall-clock seconds the stage took.
    pub seconds: f64,
}

/// How a stage went in this invocation.
#[derive(Clone, Debug)]
pub(crate) struct Outcome {
    /// The stage.
    pub def: StageDef,
    /// False when skipped (inputs unchanged).
    pub ran: bool,
    /// Its stamp.
    pub stamp: Stamp,
}

/// The run being made.
pub(crate) struct Ctx {
    /// The run folder.
    pub run: PathBuf,
    /// The merged, checked config.
    pub config: RunConfig,
    /// Training device.
    pub device: String,
    /// Hide progress bars.
    pub quiet: bool,
}

fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Content hash of a folder: every file's relative path and bytes, in sorted order
/// (stamps excluded).
pub(crate) fn hash_dir(dir: &Path) -> anyhow::Result<String> {
    fn walk(root: &Path, dir: &Path, files: &mut Vec<PathBuf>) -> anyhow::Result<()> {
        for e in std::fs::read_dir(dir).with_context(|| format!("{}", dir.display()))? {
            let e = e.with_context(|| format!("{}", dir.display()))?;
            let path = e.path();
            if e.file_type()?.is_dir() {
                walk(root, &path, files)?;
            } else if !matches!(e.file_name().to_str(), Some(".stamp.json" | ".intent.json")) {
                files.push(path.strip_prefix(root)?.to_owned());
            }
        }
        Ok(())
    }
    let mut files = Vec::new();
    walk(dir, dir, &mut files)?;
    files.sort();
    let mut h = Sha256::new();
    for f in files {
        let bytes = std::fs::read(dir.join(&f)).with_context(|| format!("{}", f.display()))?;
        h.update(f.to_string_lossy().as_bytes());
        h.update((bytes.len() as u64).to_le_bytes());
        h.update(&bytes);
    }
    Ok(hex(&h.finalize()))
}

fn read_stamp(dir: &Path) -> Option<Stamp> {
    let bytes = std::fs::read(dir.join(".stamp.json")).ok()?;
    serde_json::from_slice(&bytes).ok()
}

fn write_json(path: &Path, v: &impl Serialize) -> anyhow::Result<()> {
    let mut bytes = serde_json::to_vec_pretty(v)?;
    bytes.push(b'\n');
    write_atomic(path, &bytes)?;
    Ok(())
}

/// A path as a command-line argument.
fn arg(p: &Path) -> String {
    p.display().to_string()
}

impl Ctx {
    pub(crate) fn new(args: &RunArgs, config: &RunConfig) -> anyhow::Result<Ctx> {
        let ctx = Ctx {
            run: args.out.clone(),
            config: config.clone(),
            device: args.device.clone(),
            quiet: args.quiet,
        };
        write_json(&ctx.run.join("config/run.json"), config)?;
        Ok(ctx)
    }

    /// `<run>/<name>`.
    pub(crate) fn dir(&self, name: &str) -> PathBuf {
        self.run.join(name)
    }

    /// The config section a stage reads (what its inputs hash covers, with the
    /// upstream outputs).
    fn section(&self, name: &str) -> anyhow::Result<Value> {
        let c = &self.config;
        Ok(match name {
            "data" => match &c.import {
                Some(i) => json!({ "import": i }),
                None => serde_json::to_value(&c.data)?,
            },
            "detector" => json!({ "config": c.detector, "device": self.device }),
            "variants" => serde_json::to_value(&c.compress)?,
            "pareto" => json!({ "config": c.pareto, "device": self.pareto_device() }),
            "replay" => serde_json::to_value(&c.replay)?,
            "policy" => serde_json::to_value(&c.policy)?,
            "evaluation" => serde_json::to_value(&c.evaluation)?,
            "budget" => json!({
                "budget": c.budget,
                "heldout": c.import.is_none().then_some(&c.heldout),
                "tuning": c.import.is_none().then_some(&c.tuning),
                "evaluation": c.evaluation,
            }),
            "bundle" => json!({
                "iou_threshold": c.evaluation.iou_threshold,
                "mdp_period": c.evaluation.mdp_period,
                "reinit_period": c.evaluation.reinit_period,
                "accesses_per_image": c.evaluation.accesses_per_image,
            }),
            "flights" => serde_json::to_value(&c.flights)?,
            other => bail!("no stage named {other}"),
        })
    }

    /// The device the Pareto fronts are drawn for: the budget stage's, when its profile
    /// states both reference detectors' times (fp32, int8), so that the variants
    /// handed on are the device's front rather than this machine's.
    fn pareto_device(&self) -> Option<[f64; 2]> {
        let b = &self.config.budget;
        Some([b.device_reference_ms?, b.device_reference_int8_ms?])
    }

    /// The file a stage's command reads its config from, written now.
    /// The file is the stage's config section, except for the detector, whose section
    /// also names the device (a command-line flag, not part of the file).
    fn config_file(&self, name: &str) -> anyhow::Result<Option<PathBuf>> {
        let value = match name {
            "detector" => serde_json::to_value(&self.config.detector)?,
            "data" => match &self.config.import {
                Some(i) => serde_json::to_value(i)?,
                None => self.section(name)?,
            },
            "variants" | "policy" | "evaluation" => self.section(name)?,
            "budget" => serde_json::to_value(&self.config.budget)?,
            _ => return Ok(None),
        };
        let path = self.run.join("config").join(format!("{name}.json"));
        write_json(&path, &value)?;
        Ok(Some(path))
    }

    fn inputs_hash(&self, def: &StageDef) -> anyhow::Result<String> {
        let mut upstream = serde_json::Map::new();
        for d in def.deps {
            let stamp = read_stamp(&self.dir(d))
                .with_context(|| format!("the {d} stage has no stamp: run it first"))?;
            upstream.insert((*d).to_string(), Value::String(stamp.output_hash));
        }
        let v = json!({
            "stage": def.name,
            "pipeline": PIPELINE_VERSION,
            "frugal": env!("CARGO_PKG_VERSION"),
            "section": self.section(def.name)?,
            "upstream": upstream,
        });
        Ok(hex(&Sha256::digest(serde_json::to_string(&v)?.as_bytes())))
    }

    /// Run stage `def` (number `n`) unless its stamp matches, following the
    /// partial → stamp → rename protocol.
    pub(crate) fn stage(&self, def: &StageDef, force: bool, n: usize) -> anyhow::Result<Outcome> {
        let dir = self.dir(def.name);
        let partial = self.run.join(format!("{}.partial", def.name));
        let old = self.run.join(format!("{}.old", def.name));
        let hash = self.inputs_hash(def)?;
        let total = STAGES.len();
        let config_file = self.config_file(def.name)?;
        // a kill between the two renames of a promotion leaves the old copy behind
        if old.exists() {
            std::fs::remove_dir_all(&old).with_context(|| format!("{}", old.display()))?;
        }
        if !force {
            // killed after the stamp was written but before the rename: finish it
            if !dir.exists() && read_stamp(&partial).is_some_and(|s| s.inputs_hash == hash) {
                std::fs::rename(&partial, &dir)
                    .with_context(|| format!("moving {} into place", partial.display()))?;
            }
            if let Some(stamp) = read_stamp(&dir).filter(|s| s.inputs_hash == hash) {
                // an attempt with other inputs that was killed is of no further use
                if partial.exists() {
                    std::fs::remove_dir_all(&partial)
                        .with_context(|| format!("clearing {}", partial.display()))?;
                }
                println!(
                    "[{n}/{total}] {}: unchanged (inputs {}), skipped",
                    def.name,
                    &hash[..12]
                );
                return Ok(Outcome {
                    def: *def,
                    ran: false,
                    stamp,
                });
            }
        }
        println!("[{n}/{total}] {}: {}", def.name, def.what);
        let t0 = std::time::Instant::now();
        // only training can pick up where a killed attempt stopped; the rest restart
        let intent = partial.join(".intent.json");
        let resume = def.name == "detector"
            && std::fs::read(&intent)
                .ok()
                .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
                .is_some_and(|v| v["inputs_hash"] == hash.as_str())
            && partial.join("checkpoint/state.json").exists();
        if !resume && partial.exists() {
            std::fs::remove_dir_all(&partial)
                .with_context(|| format!("clearing {}", partial.display()))?;
        }
        std::fs::create_dir_all(&partial).with_context(|| format!("{}", partial.display()))?;
        write_json(&intent, &json!({ "inputs_hash": hash }))?;
        // the stamp quotes the commands with the final folder they are read from
        let commands = self
            .exec(def.name, &partial, config_file.as_deref(), resume)?
            .into_iter()
            .map(|c| c.replace(&arg(&partial), &arg(&dir)))
            .collect();
        let stamp = Stamp {
            stage: def.name.into(),
            inputs_hash: hash,
            output_hash: hash_dir(&partial)?,
            commands,
            config_file: config_file
                .as_ref()
                .and_then(|p| p.strip_prefix(&self.run).ok())
                .map(|p| p.display().to_string()),
            seconds: t0.elapsed().as_secs_f64(),
        };
        let _ = std::fs::remove_file(&intent);
        write_json(&partial.join(".stamp.json"), &stamp)?;
        if dir.exists() {
            std::fs::rename(&dir, &old).with_context(|| format!("{}", dir.display()))?;
        }
        std::fs::rename(&partial, &dir)
            .with_context(|| format!("moving {} into place", partial.display()))?;
        if old.exists() {
            std::fs::remove_dir_all(&old).with_context(|| format!("{}", old.display()))?;
        }
        println!("[{n}/{total}] {}: done in {:.1} s", def.name, stamp.seconds);
        Ok(Outcome {
            def: *def,
            ran: true,
            stamp,
        })
    }

    /// Run one `frugal …` command in process; returns it as a line for the stamp.
    fn frugal(&self, args: &[String]) -> anyhow::Result<String> {
        let line = format!("frugal {}", args.join(" "));
        crate::run(std::iter::once("frugal".to_string()).chain(args.iter().cloned()))
            .with_context(|| line.clone())?;
        Ok(line)
    }

    fn quiet(&self, mut args: Vec<String>) -> Vec<String> {
        if self.quiet {
            args.push("--quiet".into());
        }
        args
    }

    /// The stage's commands, writing into `out`.
    fn exec(
        &self,
        name: &str,
        out: &Path,
        config: Option<&Path>,
        resume: bool,
    ) -> anyhow::Result<Vec<String>> {
        let s = |v: &str| v.to_string();
        let cfg = || config.map(arg).unwrap_or_default();
        let c = &self.config;
        Ok(match name {
            "data" => {
                let dataset = out.join("dataset");
                let make = if c.import.is_some() {
                    "import"
                } else {
                    "generate"
                };
                vec![
                    self.frugal(&self.quiet(vec![
                        s("data"),
                        s(make),
                        s("--config"),
                        cfg(),
                        s("--out"),
                        arg(&dataset),
                    ]))?,
                    self.frugal(&[
                        s("data"),
                        s("show"),
                        arg(&dataset),
                        s("--sheet"),
                        arg(&out.join("contact_sheet.png")),
                    ])?,
                ]
            }
            "detector" => {
                let dataset = arg(&self.dir("data").join("dataset"));
                let mut train = vec![
                    s("train"),
                    s("--data"),
                    dataset.clone(),
                    s("--config"),
                    cfg(),
                    s("--out"),
                    arg(&out.join("model")),
                    s("--device"),
                    self.device.clone(),
                ];
                if resume {
                    train.push(s("--resume"));
                }
                vec![
                    self.frugal(&self.quiet(train))?,
                    self.frugal(&self.quiet(vec![
                        s("eval"),
                        s("--model"),
                        arg(&out.join("model")),
                        s("--data"),
                        dataset,
                        s("--split"),
                        s("test"),
                        s("--out"),
                        arg(&out.join("eval-test")),
                    ]))?,
                ]
            }
            "variants" => vec![self.frugal(&self.quiet(vec![
                s("compress"),
                s("--model"),
                arg(&self.dir("detector").join("model")),
                s("--data"),
                arg(&self.dir("data").join("dataset")),
                s("--out"),
                arg(out),
                s("--config"),
                cfg(),
            ]))?],
            "pareto" => {
                let mut a = vec![
                    s("pareto"),
                    s("--variants"),
                    arg(&self.dir("variants")),
                    s("--data"),
                    arg(&self.dir("data").join("dataset")),
                    s("--out"),
                    arg(out),
                    s("--threads"),
                    c.pareto.threads.to_string(),
                    s("--frames"),
                    c.pareto.frames.to_string(),
                    s("--timed-frames"),
                    c.pareto.timed_frames.to_string(),
                    s("--warmup"),
                    c.pareto.warmup.to_string(),
                    s("--threshold"),
                    c.pareto.threshold.to_string(),
                ];
                if let Some([fp32, int8]) = self.pareto_device() {
                    a.extend([
                        s("--device-reference-ms"),
                        fp32.to_string(),
                        s("--device-reference-int8-ms"),
                        int8.to_string(),
                    ]);
                }
                vec![self.frugal(&self.quiet(a))?]
            }
            "replay" => {
                let r = &c.replay;
                let log = arg(&out.join("replay.json"));
                let splits = if r.train_split == "train" {
                    "train,test"
                } else {
                    "val,test"
                };
                let mut a = self.record_args(
                    &self.dir("data").join("dataset"),
                    &log,
                    splits,
                    &r.train_split,
                );
                if r.per_combo > 0 {
                    a.extend([s("--per-combo"), r.per_combo.to_string()]);
                }
                let mut commands = vec![self.frugal(&self.quiet(a))?];
                if let Some(f) = &r.footage {
                    commands.extend(self.footage(f, out)?);
                }
                if r.calibrate {
                    commands.push(self.frugal(&[
                        s("policy"),
                        s("calibrate"),
                        s("--log"),
                        log.clone(),
                        s("--out"),
                        log,
                        s("--min-samples"),
                        r.calibrate_min_samples.to_string(),
                    ])?);
                }
                commands
            }
            "policy" => {
                let mut a = vec![
                    s("policy"),
                    s("train"),
                    s("--log"),
                    arg(&self.dir("replay").join("replay.json")),
                    s("--out"),
                    arg(out),
                    s("--config"),
                    cfg(),
                ];
                if c.replay.footage.is_some() {
                    a.extend([s("--extra-log"), arg(&self.dir("replay").join(FOOTAGE_LOG))]);
                }
                vec![self.frugal(&a)?]
            }
            "evaluation" => vec![self.frugal(&self.policy_args("eval", out, cfg()))?],
            "budget" if c.import.is_some() => {
                // imported footage: the test part is the held-out set
                let eval_cfg = self.run.join("config/evaluation.json");
                vec![
                    self.frugal(
                        &[
                            self.policy_args("budget", out, cfg()),
                            vec![s("--eval-config"), arg(&eval_cfg)],
                        ]
                        .concat(),
                    )?,
                ]
            }
            "budget" => {
                let held = out.join("heldout");
                let held_cfg = self.run.join("config/heldout.json");
                write_json(&held_cfg, &c.heldout)?;
                let held_log = arg(&held.join("replay.json"));
                let tune = out.join("tuning");
                let tune_cfg = self.run.join("config/tuning.json");
                write_json(&tune_cfg, &c.tuning)?;
                let tune_log = arg(&tune.join("replay.json"));
                // written by the evaluation stage, which runs (or is skipped) first
                let eval_cfg = self.run.join("config/evaluation.json");
                let mut cmds = Vec::new();
                for (gen_cfg, dir, log) in
                    [(&held_cfg, &held, &held_log), (&tune_cfg, &tune, &tune_log)]
                {
                    cmds.push(self.frugal(&self.quiet(vec![
                        s("data"),
                        s("generate"),
                        s("--config"),
                        arg(gen_cfg),
                        s("--out"),
                        arg(&dir.join("data")),
                    ]))?);
                    let record = self.record_args(&dir.join("data"), log, "test", "val");
                    cmds.push(self.frugal(&self.quiet(record))?);
                }
                cmds.push(
                    self.frugal(
                        &[
                            self.policy_args("budget", out, cfg()),
                            vec![
                                s("--eval-config"),
                                arg(&eval_cfg),
                                s("--heldout"),
                                held_log,
                                s("--tune"),
                                tune_log,
                            ],
                        ]
                        .concat(),
                    )?,
                );
                cmds
            }
            "bundle" => {
                let e = &c.evaluation;
                vec![
                    self.frugal(&[
                        s("bundle"),
                        s("write"),
                        s("--policy"),
                        arg(&self.dir("budget").join("policy.json")),
                        s("--out"),
                        arg(out),
                        s("--iou-threshold"),
                        e.iou_threshold.to_string(),
                        s("--mdp-period"),
                        e.mdp_period.to_string(),
                        s("--reinit-period"),
                        e.reinit_period.to_string(),
                        s("--accesses-per-image"),
                        e.accesses_per_image.to_string(),
                    ])?,
                    self.frugal(&[s("bundle"), s("verify"), arg(out)])?,
                ]
            }
            "flights" => match self.flights_skipped()? {
                Some(why) => {
                    std::fs::write(out.join("skipped.txt"), format!("{why}\n"))?;
                    Vec::new()
                }
                None => self.flights(out)?,
            },
            other => bail!("no stage named {other}"),
        })
    }

    /// Flight footage for the policy: ground-truth flights through the training mazes,
    /// recorded (`<out>/footage`), and every front variant replayed on it
    /// ([`FOOTAGE_LOG`]).
    fn footage(&self, f: &FootageSettings, out: &Path) -> anyhow::Result<Vec<String>> {
        let s = |v: &str| v.to_string();
        let mut fly = vec![s("fly")];
        for m in &f.mazes {
            fly.extend([s("--maze"), m.clone()]);
        }
        fly.extend([
            s("--seeds"),
            f.seeds.to_string(),
            s("--perception"),
            s("ground-truth"),
            s("--out"),
            arg(&out.join("footage-flights")),
            s("--record"),
            arg(&out.join("footage")),
            s("--record-every"),
            f.every.to_string(),
        ]);
        let replay = self.record_args(
            &out.join("footage"),
            &arg(&out.join(FOOTAGE_LOG)),
            "val",
            "val",
        );
        Ok(vec![
            self.frugal(&self.quiet(fly))?,
            self.frugal(&self.quiet(replay))?,
        ])
    }

    /// `frugal policy <command>` over the replay stage's log and the policy stage's
    /// policy, writing into `out`, with `config`.
    fn policy_args(&self, command: &str, out: &Path, config: String) -> Vec<String> {
        let replay = self.dir("replay").join("replay.json");
        let policy = self.dir("policy").join("policy.json");
        vec![
            "policy".into(),
            command.into(),
            "--log".into(),
            arg(&replay),
            "--policy".into(),
            arg(&policy),
            "--out".into(),
            arg(out),
            "--config".into(),
            config,
        ]
    }

    /// `frugal policy record` of the Pareto stage's variants on `data`'s `splits` into
    /// `log`, the policy learning from `train_split`, with the `[replay]` settings.
    fn record_args(&self, data: &Path, log: &str, splits: &str, train_split: &str) -> Vec<String> {
        let r = &self.config.replay;
        [
            "policy",
            "record",
            "--data",
            &arg(data),
            "--variants",
            &arg(&self.dir("pareto").join("variants.json")),
            "--out",
            log,
            "--splits",
            splits,
            "--train-split",
            train_split,
            "--threads",
            &r.threads.to_string(),
            "--max-detections",
            &r.max_detections.to_string(),
        ]
        .map(String::from)
        .to_vec()
    }

    /// The static variant of the replay evaluation (the most accurate) as an ONNX folder.
    fn static_variant(&self) -> anyhow::Result<(String, PathBuf)> {
        let eval_json = self.dir("evaluation").join("eval.json");
        let report: frugal_policies::eval::EvalReport = serde_json::from_slice(
            &std::fs::read(&eval_json).with_context(|| format!("{}", eval_json.display()))?,
        )
        .with_context(|| format!("{}", eval_json.display()))?;
        let variants = self.dir("pareto").join("variants.json");
        let file = frugal_policies::variants::VariantsFile::read(&variants)?;
        let v = file
            .variants
            .iter()
            .find(|v| v.name == report.static_variant)
            .with_context(|| {
                format!(
                    "{}: no variant {}",
                    variants.display(),
                    report.static_variant
                )
            })?;
        match &v.source {
            frugal_policies::variants::VariantSource::Onnx { dir } => {
                Ok((v.name.clone(), dir.clone()))
            }
            other => bail!(
                "the static variant {} is not an ONNX export ({other:?})",
                v.name
            ),
        }
    }

    /// Why the maze flights cannot run on this run's data, if they cannot: the maze
    /// simulator draws the synthetic signs and acts on their meanings, so the detector
    /// must know those classes.
    fn flights_skipped(&self) -> anyhow::Result<Option<String>> {
        if self.config.import.is_none() {
            return Ok(None);
        }
        let manifest = frugal_data::dataset::read_manifest(&self.dir("data").join("dataset"))?;
        let signs = frugal_data::classes();
        if manifest.classes.len() == signs.len()
            && manifest
                .classes
                .iter()
                .zip(&signs)
                .all(|(a, b)| a.name == b.name)
        {
            return Ok(None);
        }
        let names: Vec<&str> = manifest.classes.iter().map(|c| c.name.as_str()).collect();
        Ok(Some(format!(
            "no maze flights: the maze simulator shows the ten synthetic signs and acts on their meanings, and this run's detector knows other classes ({}); import with `classes = \"signs\"` to fly",
            names.join(", ")
        )))
    }

    /// Static and adaptive flights over the same mazes and seeds, and their
    /// side-by-side table and top views.
    fn flights(&self, out: &Path) -> anyhow::Result<Vec<String>> {
        let f = &self.config.flights;
        let (static_name, static_dir) = self.static_variant()?;
        // the budget stage's device flies the same: its speeds scaled by the reference
        // detectors' latencies on this machine (timed by the Pareto stage), fp32 and
        // int8, when known
        let variants = self.dir("pareto").join("variants.json");
        let file = frugal_policies::variants::VariantsFile::read(&variants)?;
        let budget = &self.config.budget;
        let same_device = f.device == budget.device;
        let slowdown = file
            .reference_ms
            .filter(|_| same_device && budget.device_reference_ms.is_some())
            .map(|h| budget.device_slowdown(Some(h)).to_string());
        let slowdown_int8 = budget
            .device_slowdown_int8(file.reference_int8_ms)
            .filter(|_| slowdown.is_some())
            .map(|s| s.to_string());
        // and the tracker's speed, by the reference tracker the budget stage timed
        // with the tracker's costs
        let budget_policy = self.dir("budget").join("policy.json");
        let slowdown_tracker = frugal_policies::TrainedPolicy::load(&budget_policy)?
            .budget
            .and_then(|b| b.config.slowdown_tracker)
            .filter(|_| slowdown.is_some())
            .map(|s| s.to_string());
        let common = |perception: &str| {
            let mut a: Vec<String> = vec!["fly".into()];
            for m in &f.mazes {
                a.extend(["--maze".into(), m.clone()]);
            }
            a.extend([
                "--seeds".into(),
                f.seeds.to_string(),
                "--seed".into(),
                f.seed.to_string(),
                "--device".into(),
                f.device.clone(),
                "--width".into(),
                f.width.to_string(),
                "--height".into(),
                f.height.to_string(),
                "--time-limit".into(),
                f.time_limit_s.to_string(),
                "--threads".into(),
                f.threads.to_string(),
                "--perception".into(),
                perception.into(),
                "--out".into(),
                arg(&out.join(perception)),
            ]);
            if let Some(s) = &slowdown {
                a.extend(["--slowdown".into(), s.clone()]);
            }
            for (flag, value) in [
                ("--slowdown-int8", &slowdown_int8),
                ("--slowdown-tracker", &slowdown_tracker),
            ] {
                if let Some(s) = value {
                    a.extend([flag.into(), s.clone()]);
                }
            }
            a
        };
        let mut st = common("static");
        st.extend(["--variant".into(), arg(&static_dir)]);
        let mut ad = common("adaptive");
        ad.extend(["--bundle".into(), arg(&self.dir("bundle"))]);
        // the config's kebab-case name is `frugal fly --carry`'s
        let carry = serde_json::to_value(f.carry)?;
        let carry = carry.as_str().context("[flights] carry is not a name")?;
        ad.extend(["--carry".into(), carry.into()]);
        if f.gif {
            ad.push("--gif".into());
        }
        // The two perceptions fly at the same time when the cores allow (each flight runs
        // ONNX Runtime on `threads` threads): the stage takes as long as the slower side
        // instead of both one after the other, and both sides see the same machine load.
        // The static side (the slower) shows the progress bar.
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let together = 2 * f.threads <= cores;
        let st = self.quiet(st);
        let (st_line, ad_line) = if together {
            ad.push("--quiet".into());
            std::thread::scope(|s| {
                let adaptive = s.spawn(|| self.frugal(&ad));
                let stat = self.frugal(&st);
                let adaptive = adaptive
                    .join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("the adaptive flights panicked")));
                (stat, adaptive)
            })
        } else {
            (self.frugal(&st), self.frugal(&self.quiet(ad)))
        };
        let commands = vec![st_line?, ad_line?];
        let rows = super::flights::compare_flights(out, &self.config, &static_name)?;
        write_json(&out.join("comparison.json"), &rows)?;
        Ok(commands)
    }
}
