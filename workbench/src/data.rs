//! `frugal data …`: generate the synthetic dataset, summarise it, draw its boxes,
//! import real datasets and export to COCO.
use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use frugal_data::{Clutter, Dataset, GenConfig, ImportSettings, Light, Split, show};
use std::path::{Path, PathBuf};

/// Arguments of `frugal data`.
#[derive(Args, Debug)]
pub struct DataArgs {
    #[command(subcommand)]
    command: DataCommand,
}

#[derive(Subcommand, Debug)]
enum DataCommand {
    /// Render the synthetic dataset: warehouse videos with signs, exact boxes, COCO
    /// annotations per split and a manifest.
    ///
    /// Same config and seed give byte-identical output. The default config makes 396
    /// videos at 480×270 (3 clutter × 2 light levels × 66 videos, split 60 train / 2
    /// val / 4 test per combination): 6-frame training clips, 60-frame val and test
    /// clips, 4,320 frames.
    Generate(GenerateArgs),
    /// Print counts per split, per scenario level and per class, and box sizes.
    Summary {
        /// The dataset folder.
        dir: PathBuf,
        /// Print JSON instead of tables.
        #[arg(long)]
        json: bool,
    },
    /// Draw boxes and class labels onto frames (PNG) so a person can check them, and/or
    /// make a contact sheet: a grid of annotated thumbnails across every scenario level.
    Show(ShowArgs),
    /// Import a real dataset (COCO JSON, Pascal VOC XML, GTSDB-style CSV; video files or
    /// image folders with MOT, CVAT for video, COCO-video or ImageNet VID annotations) into frugal's
    /// dataset form: frames, COCO per split, manifest.
    ///
    /// The dataset keeps the source's classes (renamed or merged with --class-map), or
    /// maps them onto the ten signs (--classes signs) or a list of your own. Images
    /// without video information become one video each and are split by a fixed hash
    /// of the video id unless --split is given; a video is cut into train / val / test
    /// parts in time order (--time-split, the default below three videos).
    Import(Box<ImportArgs>),
    /// Export a dataset with its frames: as a COCO folder (annotations.json,
    /// category_id = class id + 1, images carry video, index, split), as MOT Challenge
    /// sequences (<video>/gt/gt.txt, labels.txt, seqinfo.ini, img1/), or as COCO with
    /// videos (TAO / YouTube-VIS style annotations.json). Each imports back as it was.
    Export {
        /// Output format.
        #[arg(long, value_enum, default_value = "coco")]
        format: ExportFormat,
        /// The dataset folder.
        dir: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Export only this split (train, val or test).
        #[arg(long, value_parser = parse_split)]
        split: Option<Split>,
    },
}

/// Options of `frugal data show`.
#[derive(Args, Debug)]
struct ShowArgs {
    /// The dataset folder.
    dir: PathBuf,
    /// Write annotated frames into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Only frames of this split (train, val or test).
    #[arg(long, value_parser = parse_split)]
    split: Option<Split>,
    /// Only frames of this video.
    #[arg(long)]
    video: Option<u32>,
    /// How many frames to write (spread evenly over the selection).
    #[arg(long, default_value_t = 12)]
    frames: usize,
    /// Write a contact sheet to this PNG file.
    #[arg(long)]
    sheet: Option<PathBuf>,
    /// Contact sheet: thumbnails per row.
    #[arg(long, default_value_t = 4)]
    cols: u32,
    /// Contact sheet: thumbnail size WxH.
    #[arg(long, default_value = "240x135", value_parser = parse_size)]
    thumb: (u32, u32),
    /// Contact sheet: frames per scenario level (clutter × light).
    #[arg(long, default_value_t = 2)]
    per_level: u32,
}

/// Options of `frugal data import`.
#[derive(Args, Debug)]
struct ImportArgs {
    /// Source format: coco, voc, gtsdb (still images); mot, cvat, coco-video,
    /// imagenet-vid (video annotations).
    #[arg(long, required_unless_present = "config")]
    format: Option<String>,
    /// The annotation file (COCO / COCO-video JSON, MOT gt.txt, CVAT XML, GTSDB CSV) or
    /// folder (VOC, ImageNet VID).
    #[arg(required_unless_present = "config")]
    input: Option<PathBuf>,
    /// Read every import setting from this TOML or JSON file (the `[import]` section of
    /// a run config); the flags below are then ignored.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output dataset folder.
    #[arg(long)]
    out: PathBuf,
    /// Folder the image paths are relative to (default: the annotation file's folder).
    #[arg(long)]
    images: Option<PathBuf>,
    /// Video formats: the video file (MP4, AVI, MKV, MOV, … decoded by ffmpeg) or
    /// image folder holding the frames (default: the images the annotations name, or
    /// MOT's img1/).
    #[arg(long)]
    video: Option<PathBuf>,
    /// Frame rate of an image folder (default: the annotations', else 30).
    #[arg(long)]
    fps: Option<f64>,
    /// Keep one frame in N.
    #[arg(long, default_value_t = 0)]
    every: u32,
    /// Keep at most F frames per second.
    #[arg(long)]
    sample_fps: Option<f64>,
    /// Start of the time window, seconds.
    #[arg(long)]
    start: Option<f64>,
    /// End of the time window, seconds.
    #[arg(long)]
    end: Option<f64>,
    /// Cut each video into consecutive train,val,test parts of these fractions, e.g.
    /// 0.7,0.15,0.15 (default for sets of fewer than three videos).
    #[arg(long, value_parser = parse_fractions)]
    time_split: Option<[f64; 3]>,
    /// JSON or TOML map from source class (name or numeric id) to the class it becomes,
    /// e.g. {"14": "stop", "33": "turn_right", "person": "pedestrian"}.
    #[arg(long)]
    class_map: Option<PathBuf>,
    /// With --class-map: keep only the mapped classes. With --classes other than
    /// `source`: drop objects of other classes instead of failing.
    #[arg(long)]
    drop_unmapped: bool,
    /// The dataset's classes: `source` (the source's own, any number and names),
    /// `signs` (the ten synthetic signs, by name or road sign code), or a file with one
    /// class name per line.
    #[arg(long, default_value = "source")]
    classes: String,
    /// What the drone does on a class, CLASS=ACTION (turn_left, turn_right, stop, wait);
    /// repeat for several, e.g. --action pedestrian=wait.
    #[arg(long = "action", value_parser = frugal_data::parse_action)]
    actions: Vec<(String, frugal_data::NavAction)>,
    /// The class of MOT files without a class column.
    #[arg(long, default_value = "pedestrian")]
    default_class: String,
    /// MOT: boxes less visible than this (0-1) are marked ignore.
    #[arg(long, default_value_t = 0.0)]
    min_visibility: f32,
    /// Images listed but missing are an error (default: skipped and counted).
    #[arg(long)]
    strict: bool,
    /// Put every image into this split (train, val or test).
    #[arg(long, value_parser = parse_split)]
    split: Option<Split>,
    /// Clutter level recorded for the imported videos.
    #[arg(long, value_enum, default_value = "medium")]
    clutter: ClutterArg,
    /// Light level recorded for the imported videos.
    #[arg(long, value_enum, default_value = "normal")]
    light: LightArg,
    /// Hide the progress bar.
    #[arg(long)]
    quiet: bool,
}

impl ImportArgs {
    /// The settings the flags (or the --config file) describe.
    fn settings(&self) -> anyhow::Result<ImportSettings> {
        if let Some(path) = &self.config {
            return Ok(ImportSettings::from_file(path)?);
        }
        let (Some(format), Some(input)) = (&self.format, &self.input) else {
            anyhow::bail!("give --format and the annotation file, or --config");
        };
        let mut s = ImportSettings::new(format, input);
        s.images.clone_from(&self.images);
        s.video.clone_from(&self.video);
        s.fps = self.fps;
        s.every = self.every;
        s.sample_fps = self.sample_fps;
        s.start_s = self.start;
        s.end_s = self.end;
        s.time_split = self.time_split;
        s.split = self.split;
        s.classes.clone_from(&self.classes);
        if let Some(map) = &self.class_map {
            s.class_map = frugal_data::import::classes::read_class_map(map)?;
        }
        s.drop_unmapped = self.drop_unmapped;
        s.actions = self.actions.iter().cloned().collect();
        s.default_class.clone_from(&self.default_class);
        s.min_visibility = self.min_visibility;
        s.strict = self.strict;
        s.clutter = match self.clutter {
            ClutterArg::Low => Clutter::Low,
            ClutterArg::Medium => Clutter::Medium,
            ClutterArg::High => Clutter::High,
        };
        s.light = match self.light {
            LightArg::Normal => Light::Normal,
            LightArg::Low => Light::Low,
        };
        Ok(s)
    }
}

fn parse_fractions(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    <[f64; 3]>::try_from(v).map_err(|_| format!("{s:?}: give three fractions train,val,test"))
}

#[derive(ValueEnum, Debug, Clone, Copy)]
enum ExportFormat {
    /// COCO JSON, still images with frugal's extras.
    Coco,
    /// MOT Challenge sequences, one per video.
    Mot,
    /// COCO with videos.
    CocoVideo,
}

#[derive(ValueEnum, Debug, Clone, Copy)]
enum ClutterArg {
    Low,
    Medium,
    High,
}

#[derive(ValueEnum, Debug, Clone, Copy)]
enum LightArg {
    Normal,
    Low,
}

/// Generator options; each flag overrides the config file, which overrides the
/// built-in defaults.
#[derive(Args, Debug, Clone, Default)]
pub struct GenerateArgs {
    /// A TOML or JSON config file (unknown keys are rejected, missing keys keep the
    /// built-in defaults; --profile is then ignored); see `frugal_data::GenConfig`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output folder (replaced only once the new dataset is complete).
    #[arg(long, default_value = "runs/default/data")]
    pub out: PathBuf,
    /// Global seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Videos per (clutter, light) combination.
    #[arg(long)]
    pub videos: Option<u32>,
    /// Frames per video.
    #[arg(long)]
    pub frames: Option<u32>,
    /// Frame width in pixels.
    #[arg(long)]
    pub width: Option<u32>,
    /// Frame height in pixels.
    #[arg(long)]
    pub height: Option<u32>,
    /// Start from a built-in profile instead of the defaults.
    #[arg(long, value_enum)]
    pub profile: Option<Profile>,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Built-in generator profiles.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Profile {
    /// The default dataset (4,320 frames at 480×270).
    Default,
    /// 216 frames at 320×180 (3 videos per level, 12 frames each), for a quick look.
    Quick,
    /// 54 frames at 192×108 (3 videos per level, 3 frames each), for tests.
    Tiny,
}

impl GenerateArgs {
    /// The effective config: profile or defaults, then the file, then the flags.
    pub fn config(&self) -> anyhow::Result<GenConfig> {
        let mut c = match &self.config {
            Some(path) => GenConfig::from_file(path)?,
            None => match self.profile.unwrap_or(Profile::Default) {
                Profile::Default => GenConfig::default(),
                Profile::Quick => GenConfig::quick(),
                Profile::Tiny => GenConfig::tiny(),
            },
        };
        if let Some(s) = self.seed {
            c.seed = s;
        }
        if let Some(v) = self.videos {
            c.videos_per_combo = v;
        }
        if let Some(f) = self.frames {
            c.frames_per_video = f;
        }
        if let Some(w) = self.width {
            c.width = w;
        }
        if let Some(h) = self.height {
            c.height = h;
        }
        c.validate(Path::new("command-line options"))?;
        Ok(c)
    }
}

/// Run `frugal data …`.
pub fn run(args: DataArgs) -> anyhow::Result<()> {
    match args.command {
        DataCommand::Generate(g) => {
            let config = g.config()?;
            let ds = frugal_data::generate(&config, &g.out, !g.quiet)
                .with_context(|| format!("generating into {}", g.out.display()))?;
            println!("wrote {} frames to {}", ds.frames.len(), g.out.display());
            print!("{}", frugal_data::summary(&ds));
            Ok(())
        }
        DataCommand::Show(a) => show(a),
        DataCommand::Import(a) => {
            let mut opts = a.settings()?.options()?;
            opts.progress = !a.quiet;
            let ds = frugal_data::import(&opts, &a.out)?;
            println!(
                "imported {} frames into {}",
                ds.frames.len(),
                a.out.display()
            );
            print_counts(&a.out)?;
            print!("{}", frugal_data::summary(&ds));
            Ok(())
        }
        DataCommand::Export {
            format,
            dir,
            out,
            split,
        } => {
            use frugal_data::annotations::AnnotationFormat;
            let ds = Dataset::load(&dir)?;
            let written = match format {
                ExportFormat::Coco => frugal_data::export_coco(&ds, split, &out)?,
                ExportFormat::Mot => {
                    frugal_data::export_video(&ds, split, AnnotationFormat::Mot, &out)?
                }
                ExportFormat::CocoVideo => {
                    frugal_data::export_video(&ds, split, AnnotationFormat::CocoVideo, &out)?
                }
            };
            println!("wrote {}", written.display());
            Ok(())
        }
        DataCommand::Summary { dir, json } => {
            let ds = Dataset::load(&dir)?;
            let s = frugal_data::summary(&ds);
            if json {
                println!("{}", serde_json::to_string_pretty(&s)?);
            } else {
                print!("{s}");
            }
            Ok(())
        }
    }
}

fn show(a: ShowArgs) -> anyhow::Result<()> {
    if a.out.is_none() && a.sheet.is_none() {
        anyhow::bail!(
            "nothing to do: give --out DIR for annotated frames and/or --sheet FILE for a contact sheet"
        );
    }
    let ds = Dataset::load(&a.dir)?;
    if let Some(out) = &a.out {
        let selected: Vec<_> = ds
            .frames
            .iter()
            .filter(|f| {
                a.split.is_none_or(|s| f.split == s) && a.video.is_none_or(|v| f.video == v)
            })
            .collect();
        if selected.is_empty() {
            anyhow::bail!("{}: no frames match the selection", a.dir.display());
        }
        let n = a.frames.clamp(1, selected.len());
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        for k in 0..n {
            let f = selected[k * selected.len() / n];
            let img = show::annotated_frame(&ds, f)?;
            let path = out.join(format!("v{:04}_{:06}.png", f.video, f.index));
            show::save_png(&img, &path)?;
        }
        println!("wrote {n} annotated frames to {}", out.display());
    }
    if let Some(sheet) = &a.sheet {
        let opts = show::SheetOptions {
            cols: a.cols,
            thumb_w: a.thumb.0,
            thumb_h: a.thumb.1,
            per_level: a.per_level,
        };
        let img = show::contact_sheet(&ds, &opts)?;
        show::save_png(&img, sheet)?;
        println!(
            "wrote contact sheet {} ({}x{})",
            sheet.display(),
            img.width(),
            img.height()
        );
    }
    Ok(())
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("expected WxH, got {s:?}"))?;
    let p = |v: &str| {
        v.parse::<u32>()
            .ok()
            .filter(|&v| v >= 16)
            .ok_or_else(|| format!("bad size {s:?}"))
    };
    Ok((p(w)?, p(h)?))
}

/// Parse a split name (for `--split`).
pub fn parse_split(s: &str) -> Result<Split, String> {
    match s {
        "train" => Ok(Split::Train),
        "val" => Ok(Split::Val),
        "test" => Ok(Split::Test),
        other => Err(format!("unknown split {other:?} (train, val or test)")),
    }
}

/// What an import skipped or changed, from the manifest it wrote.
fn print_counts(out: &std::path::Path) -> anyhow::Result<()> {
    if let frugal_data::Source::Imported { counts, .. } =
        frugal_data::dataset::read_manifest(out)?.source
        && !counts.is_zero()
    {
        println!(
            "skipped {} missing images; clipped {} boxes to their image; {} boxes marked ignore",
            counts.missing_images, counts.clipped_boxes, counts.ignored_boxes
        );
    }
    Ok(())
}
