//! [`generate`]: render every planned video in parallel (one rayon task per video,
//! each seeded only from its own id, so thread scheduling cannot change a byte) into
//! `<out>.partial-XXXX`, then write the annotations and manifest and swap the folder
//! into place.
use crate::dataset::{PartialDir, read_manifest};
use crate::video::{RenderOptions, Video, video_seed};
use crate::{
    DataError, Dataset, FrameRecord, GENERATOR_VERSION, GenConfig, Source, VideoMeta, VideoPlan,
    classes,
};
use image::ImageEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The path of a frame, relative to the dataset root: `frames/v0007/000012.png`.
pub fn frame_file(video: u32, index: u32) -> PathBuf {
    PathBuf::from(format!("frames/v{video:04}/{index:06}.png"))
}

/// Encode an RGB image as PNG bytes.
pub fn encode_png(img: &image::RgbImage, path: &Path) -> Result<Vec<u8>, DataError> {
    let mut bytes = Vec::new();
    PngEncoder::new_with_quality(&mut bytes, CompressionType::Fast, FilterType::Adaptive)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| DataError::image(path, e))?;
    Ok(bytes)
}

fn render_video(
    config: &GenConfig,
    plan: &VideoPlan,
    dir: &Path,
    pb: &ProgressBar,
) -> Result<(VideoMeta, Vec<FrameRecord>), DataError> {
    let seed = video_seed(config.seed, plan.id);
    let video = Video::new(config, plan, seed);
    let vdir = dir.join(format!("frames/v{:04}", plan.id));
    std::fs::create_dir_all(&vdir).map_err(|e| DataError::io(&vdir, e))?;
    let mut frames = Vec::with_capacity(plan.frames as usize);
    for index in 0..plan.frames {
        let f = video.frame(index, &RenderOptions::default());
        let file = frame_file(plan.id, index);
        let path = dir.join(&file);
        let bytes = encode_png(&f.rgb, &path)?;
        std::fs::write(&path, bytes).map_err(|e| DataError::io(&path, e))?;
        frames.push(FrameRecord {
            id: plan.first_frame + u64::from(index),
            file,
            width: config.width,
            height: config.height,
            video: plan.id,
            index,
            split: plan.split,
            objects: f.objects,
            ignore: Vec::new(),
            time_s: None,
        });
        pb.inc(1);
    }
    let meta = VideoMeta {
        id: plan.id,
        seed,
        clutter: plan.clutter,
        light: plan.light,
        split: plan.split,
        frames: plan.frames,
        name: None,
        fps: None,
    };
    Ok((meta, frames))
}

/// Generate the synthetic dataset described by `config` into `out` (replacing what is
/// there only once the new dataset is complete). Besides frames, annotations and the
/// manifest (which records the config and its hash), `out/config.toml` holds the config
/// so that `frugal data generate --config out/config.toml` reproduces the dataset. With `progress`, a progress bar is
/// drawn on stderr.
pub fn generate(config: &GenConfig, out: &Path, progress: bool) -> Result<Dataset, DataError> {
    config.validate(Path::new("<config>"))?;
    let plan = config.video_plan();
    let partial = PartialDir::new(out)?;
    let pb = if progress {
        let pb = ProgressBar::new(config.total_frames());
        if let Ok(style) = ProgressStyle::with_template(
            "{msg} [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta}",
        ) {
            pb.set_style(style.progress_chars("=> "));
        }
        pb.set_message("generating");
        pb
    } else {
        ProgressBar::hidden()
    };
    let results: Vec<(VideoMeta, Vec<FrameRecord>)> = plan
        .par_iter()
        .map(|p| render_video(config, p, partial.path(), &pb))
        .collect::<Result<_, _>>()?;
    pb.finish_and_clear();
    let mut videos = Vec::with_capacity(results.len());
    let mut frames = Vec::new();
    for (meta, f) in results {
        videos.push(meta);
        frames.extend(f);
    }
    let mut dataset = Dataset {
        root: partial.path().to_owned(),
        classes: classes(),
        videos,
        frames,
    };
    dataset.write_metadata(
        partial.path(),
        Source::Synthetic {
            config: config.clone(),
            config_hash: config.hash(),
            generator_version: GENERATOR_VERSION,
        },
    )?;
    // The config again as TOML, ready for `frugal data generate --config`.
    let config_path = partial.path().join("config.toml");
    let toml = toml::to_string(config).map_err(|e| DataError::Config {
        path: config_path.clone(),
        message: e.to_string(),
    })?;
    crate::dataset::write_atomic(&config_path, toml.as_bytes())?;
    partial.commit()?;
    dataset.root = out.to_owned();
    Ok(dataset)
}

/// Like [`generate`], but when `out` already holds a dataset generated from the same
/// config (same [`GenConfig::hash`]) it is loaded instead. Returns the dataset and
/// whether it was reused.
pub fn generate_or_reuse(
    config: &GenConfig,
    out: &Path,
    progress: bool,
) -> Result<(Dataset, bool), DataError> {
    if let Ok(manifest) = read_manifest(out)
        && let Source::Synthetic { config_hash, .. } = &manifest.source
        && *config_hash == config.hash()
        && let Ok(ds) = Dataset::load(out)
    {
        return Ok((ds, true));
    }
    Ok((generate(config, out, progress)?, false))
}
