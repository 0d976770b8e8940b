//! The policy bundle on disk: the runtime's binary format (written with its
//! `BundleWriter`) plus the variants' ONNX files copied beside it, every file's SHA-256
//! recorded in the bundle; `verify` re-hashes them, `inspect` prints a bundle.
//!
//! Layout of a bundle folder:
//!
//! ```text
//! <dir>/policy.frpb                     the runtime bundle
//! <dir>/onnx/<variant>/<graph>.onnx     every ONNX graph of every ONNX variant
//! ```
//!
//! The format has one file slot per variant; an exported CNN has two graphs. The slot
//! holds the backbone graph (`backbone_rpn.onnx`, or the first graph by name) and
//! every further graph is listed in the metadata as `file:<relative path>` =
//! `<sha256 hex>`; `verify` checks both kinds. A HoG variant's feature model is
//! copied once to `hog/<file>` (a `file:` entry) and the variant is described by the
//! metadata entry `hog:<variant>` = `<file> <parameter tuple>`.

use crate::error::{PolicyError, Result};
use crate::train::TrainedPolicy;
use crate::variants::{FamilyInfo, Precision, VariantInfo, VariantSource};
use frugal_runtime::Bundle;
use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, ScheduleSpec, VariantSpec};
use frugal_runtime::bundle::{Bucket, Thresholds};
use sha2::{Digest, Sha256};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The bundle's file name inside a bundle folder, and the metadata key prefix of extra
/// files: the drone side's, which reads and checks what this module writes.
pub use frugal_nav::bundle::{BUNDLE_FILE, FILE_KEY, FP32, INT8, PRECISION_KEY};
/// The graph that takes the variant's file slot when present.
pub const PRIMARY_GRAPH: &str = "backbone_rpn.onnx";

/// A variant's file as stored in the bundle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VariantFiles {
    /// The slot file (relative to the bundle folder) and its hash; `None` for variants
    /// without ONNX graphs.
    pub primary: Option<(String, [u8; 32])>,
    /// Further files and their hashes.
    pub extra: Vec<(String, [u8; 32])>,
}

/// Lower-case hex of a digest.
pub fn hex(d: &[u8]) -> String {
    d.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// SHA-256 of a file.
pub fn sha256_file(path: &Path) -> Result<[u8; 32]> {
    let bytes = std::fs::read(path).map_err(|e| PolicyError::io(path, e))?;
    Ok(Sha256::digest(&bytes).into())
}

/// The bytes of a bundle: thresholds, families, variants (with files), a policy table
/// and metadata. Checked by the runtime's reader before they are returned.
#[allow(clippy::too_many_arguments)]
pub fn bundle_bytes(
    families: &[FamilyInfo],
    variants: &[VariantInfo],
    files: &[VariantFiles],
    thresholds: Thresholds,
    initial: u16,
    reference: Option<u16>,
    actions: &[u16],
    schedules: Option<ScheduleSpec>,
    metadata: &[(String, String)],
) -> Result<Vec<u8>> {
    let mut w = BundleWriter::new(thresholds);
    for f in families {
        w = w.family(FamilySpec {
            name: f.name.clone(),
            buckets: f.buckets.to_runtime(),
        });
    }
    for (i, v) in variants.iter().enumerate() {
        let mut spec = VariantSpec::new(
            &v.name,
            v.family as u16,
            v.relative_cost as f32,
            v.latency_ms as f32,
        );
        if let Some(VariantFiles {
            primary: Some((file, sha)),
            ..
        }) = files.get(i)
        {
            spec.onnx_file = file.clone();
            spec.sha256 = *sha;
        }
        w = w.variant(spec);
    }
    w = w.policy(initial, actions.to_vec());
    if let Some(r) = reference {
        w = w.reference(r);
    }
    if let Some(s) = schedules {
        w = w.schedules(s);
    }
    for (k, v) in metadata {
        w = w.metadata(k.clone(), v.clone());
    }
    for f in files {
        for (file, sha) in &f.extra {
            w = w.metadata(format!("{FILE_KEY}{file}"), hex(sha));
        }
    }
    w.finish().map_err(|e| PolicyError::Bundle {
        path: "<memory>".into(),
        message: e.to_string(),
    })
}

/// The metadata a trained policy puts into its bundle: how it was made, and each
/// variant's precision (`precision:<variant>` = `int8` or `fp32`, read by a simulated
/// device that charges int8 by its own speed).
pub fn policy_metadata(policy: &TrainedPolicy) -> Vec<(String, String)> {
    let c = &policy.config;
    let precisions = policy.variants.iter().map(|v| {
        let p = match v.precision {
            Precision::Int8 => INT8,
            Precision::Fp32 => FP32,
        };
        (format!("{PRECISION_KEY}{}", v.name), p.to_owned())
    });
    let mut meta = vec![
        (
            "created-by".into(),
            format!("frugal {}", env!("CARGO_PKG_VERSION")),
        ),
        ("mdp.alpha".into(), c.alpha.to_string()),
        ("mdp.gamma".into(), c.gamma.to_string()),
        (
            "mdp.weights".into(),
            format!(
                "opt={} ge={} ua={} miss={}",
                c.weights.opt, c.weights.ge, c.weights.ua, c.weights.miss
            ),
        ),
        (
            "mdp.training-videos".into(),
            policy
                .training_videos
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join(","),
        ),
    ];
    meta.extend(precisions);
    meta
}

/// A trained policy's bundle bytes without files (what the replay evaluates).
pub fn policy_bundle(policy: &TrainedPolicy, thresholds: Thresholds) -> Result<Vec<u8>> {
    bundle_bytes(
        &policy.families,
        &policy.variants,
        &[],
        thresholds,
        policy.initial,
        policy.reference,
        &policy.actions,
        policy.budget.as_ref().map(|b| b.schedule_spec()),
        &policy_metadata(policy),
    )
}

fn safe_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Write a bundle folder for `policy` into `out` (built beside it and swapped into
/// place when complete): ONNX graphs copied and hashed, the bundle written last.
/// Returns the bundle file's path.
pub fn write_bundle(policy: &TrainedPolicy, thresholds: Thresholds, out: &Path) -> Result<PathBuf> {
    let partial = frugal_data::dataset::PartialDir::new(out)?;
    let root = partial.path().to_owned();
    let mut files = Vec::with_capacity(policy.variants.len());
    let mut hog_meta: Vec<(String, String)> = Vec::new();
    let mut hog_files: Vec<(String, [u8; 32])> = Vec::new();
    for v in &policy.variants {
        let mut vf = VariantFiles::default();
        if let VariantSource::Hog { model, params } = &v.source {
            let name = model
                .file_name()
                .map(|n| safe_name(&n.to_string_lossy()))
                .unwrap_or_else(|| "model.json".into());
            let rel = format!("hog/{name}");
            if !hog_files.iter().any(|(f, _)| *f == rel) {
                std::fs::create_dir_all(root.join("hog"))
                    .map_err(|e| PolicyError::io(root.join("hog"), e))?;
                std::fs::copy(model, root.join(&rel)).map_err(|e| PolicyError::io(model, e))?;
                hog_files.push((rel.clone(), sha256_file(&root.join(&rel))?));
            }
            hog_meta.push((format!("hog:{}", v.name), format!("{rel} {params}")));
        }
        if let VariantSource::Onnx { dir } = &v.source {
            let entries = std::fs::read_dir(dir).map_err(|e| PolicyError::io(dir, e))?;
            let mut graphs: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "onnx"))
                .collect();
            graphs.sort_by_key(|p| (p.file_name() != Some(PRIMARY_GRAPH.as_ref()), p.clone()));
            if graphs.is_empty() {
                return Err(PolicyError::invalid(
                    dir,
                    format!("variant {}", v.name),
                    "no .onnx files in the variant's folder",
                ));
            }
            let sub = Path::new("onnx").join(safe_name(&v.name));
            std::fs::create_dir_all(root.join(&sub))
                .map_err(|e| PolicyError::io(root.join(&sub), e))?;
            for g in &graphs {
                let name = g
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let rel = sub.join(&name);
                std::fs::copy(g, root.join(&rel)).map_err(|e| PolicyError::io(g, e))?;
                let sha = sha256_file(&root.join(&rel))?;
                let rel = rel.to_string_lossy().replace('\\', "/");
                if vf.primary.is_none() {
                    vf.primary = Some((rel, sha));
                } else {
                    vf.extra.push((rel, sha));
                }
            }
        }
        files.push(vf);
    }
    if let Some(first) = files.first_mut() {
        first.extra.extend(hog_files);
    }
    let mut metadata = policy_metadata(policy);
    metadata.extend(hog_meta);
    let bytes = bundle_bytes(
        &policy.families,
        &policy.variants,
        &files,
        thresholds,
        policy.initial,
        policy.reference,
        &policy.actions,
        policy.budget.as_ref().map(|b| b.schedule_spec()),
        &metadata,
    )?;
    frugal_data::dataset::write_atomic(&root.join(BUNDLE_FILE), &bytes)?;
    partial.commit()?;
    Ok(out.join(BUNDLE_FILE))
}

/// The bundle file of a path that is a bundle folder or the file itself.
pub fn bundle_path(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join(BUNDLE_FILE)
    } else {
        path.to_owned()
    }
}

/// Read a bundle file and parse it with the runtime's reader.
pub fn read_bundle(path: &Path) -> Result<Vec<u8>> {
    let file = bundle_path(path);
    let bytes = std::fs::read(&file).map_err(|e| PolicyError::io(&file, e))?;
    Bundle::parse(&bytes).map_err(|e| PolicyError::Bundle {
        path: file.clone(),
        message: e.to_string(),
    })?;
    Ok(bytes)
}

/// Check a bundle: the runtime parses it and every referenced file exists and hashes
/// to what the bundle says ([`frugal_nav::bundle::verify_bundle_file`], the check the
/// drone makes at start). Returns the files checked.
pub fn verify(path: &Path) -> Result<Vec<PathBuf>> {
    use frugal_nav::bundle::BundleError;
    let file = bundle_path(path);
    frugal_nav::bundle::verify_bundle_file(&file).map_err(|e| match e {
        BundleError::Io { path, source } => PolicyError::io(path, source),
        BundleError::Parse { path, message } => PolicyError::Bundle { path, message },
        BundleError::Missing { path, bundle } => PolicyError::invalid(
            &path,
            "file",
            format!("referenced by {} but missing", bundle.display()),
        ),
        BundleError::Hash {
            path,
            expected,
            actual,
        } => PolicyError::Hash {
            path,
            expected,
            actual,
        },
        other => PolicyError::Bundle {
            path: file.clone(),
            message: other.to_string(),
        },
    })
}

/// A readable description of a bundle.
pub fn inspect(path: &Path) -> Result<String> {
    let file = bundle_path(path);
    let bytes = read_bundle(&file)?;
    let b = Bundle::parse(&bytes).map_err(|e| PolicyError::Bundle {
        path: file.clone(),
        message: e.to_string(),
    })?;
    let mut s = String::new();
    let t = b.thresholds();
    let _ = writeln!(s, "bundle {} ({} bytes)", file.display(), bytes.len());
    let _ = writeln!(
        s,
        "thresholds: θ_th (IoU) {}  T_m (track quality) {}  N (MDP period) {}  M (re-init period) {}  MDP accesses per image {}",
        t.iou_threshold, t.min_track_quality, t.mdp_period, t.reinit_period, t.accesses_per_image
    );
    let _ = writeln!(s, "families:");
    for i in 0..b.family_count() {
        if let Some(f) = b.family(i) {
            let k = f.buckets;
            let _ = writeln!(
                s,
                "  {i}: {:<12} c_opt {:>6}  c_ge {:>6}  c_ua {:>6}  T_c {:>6}",
                f.name, k.c_opt, k.c_ge, k.c_ua, k.t_c
            );
        }
    }
    let _ = writeln!(s, "variants:");
    let _ = writeln!(
        s,
        "  {:>3}  {:<24} {:>6} {:>10} {:>8}  file (sha256)",
        "id", "name", "family", "latency ms", "rel cost"
    );
    for (id, v) in b.variants() {
        let file = if v.onnx_file.is_empty() {
            "-".to_owned()
        } else {
            format!("{} ({}…)", v.onnx_file, &hex(&v.sha256)[..16])
        };
        let _ = writeln!(
            s,
            "  {id:>3}  {:<24} {:>6} {:>10.3} {:>8.3}  {file}",
            v.name, v.family, v.latency_ms, v.relative_cost
        );
    }
    let pol = b.policy();
    let name = |v: u16| b.variant(v).map_or("?".to_owned(), |x| x.name.to_owned());
    let _ = writeln!(
        s,
        "policy (initial variant: {}; reference variant, to confirm signs: {}):",
        name(pol.initial()),
        name(pol.reference())
    );
    let _ = writeln!(
        s,
        "  {:<24} {:>14} {:>14} {:>14} {:>14}",
        "current \\ bucket", "optimal", "good enough", "inadequate", "miss"
    );
    for (v, var) in b.variants() {
        let _ = write!(s, "  {:<24}", var.name);
        for bucket in Bucket::ALL {
            let a = pol.action(bucket, v).map_or("?".to_owned(), name);
            let _ = write!(s, " {a:>14}");
        }
        s.push('\n');
    }
    if let Some(sch) = b.schedules() {
        let periods: Vec<String> = (0..sch.period_count())
            .filter_map(|i| sch.period(i))
            .map(|p| p.to_string())
            .collect();
        let clock = sch.frame_ms().map_or_else(
            || "frames of the camera (format 5 or older: the tables' rate is not recorded)".into(),
            |ms| format!("frames of {ms:.2} ms ({:.1} fps)", 1e3 / ms),
        );
        let _ = writeln!(
            s,
            "schedules: {} budget tables, detect every {} frames; periods and budgets count {clock}",
            sch.budget_count(),
            periods.join(" / ")
        );
        for k in 0..sch.budget_count() {
            if let Some(i) = sch.budget(k) {
                let _ = writeln!(
                    s,
                    "  budget {k}: {} ms per frame (slowdown {}), expected {:.2} ms, P95 {:.2} ms",
                    i.budget_ms, i.slowdown, i.expected_ms, i.p95_ms
                );
            }
        }
    } else {
        let _ = writeln!(s, "schedules: none (the paper's MDP table only)");
    }
    let _ = writeln!(s, "metadata:");
    for (k, v) in b.metadata() {
        let _ = writeln!(s, "  {k} = {v}");
    }
    Ok(s)
}
