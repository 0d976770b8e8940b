//! `frugal data …`: generate the synthetic dataset, summarise it, draw its boxes,
//! import real datasets and export to COCO.
use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use frugal_data::{Dataset, GenConfig, Split};
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
    /// Same config and seed give byte-identical output. The default config makes 48
    /// videos (3 clutter × 2 light levels × 8 videos, split 5 train / 1 val / 2 test
    /// per combination) of 60 frames at 480×270.
    Generate(GenerateArgs),
    /// Print counts per split, per scenario level and per class, and box sizes.
    Summary {
        /// The dataset folder.
        dir: PathBuf,
        /// Print JSON instead of tables.
        #[arg(long)]
        json: bool,
    },
}

/// Generator options; each flag overrides the config file, which overrides the
/// built-in defaults.
#[derive(Args, Debug, Clone, Default)]
pub struct GenerateArgs {
    /// A TOML or JSON config file (unknown keys are rejected); see `frugal_data::GenConfig`.
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
    /// The default dataset (2,880 frames at 480×270).
    Default,
    /// 360 frames at 320×180, for a quick look.
    Quick,
    /// 54 frames at 192×108, for tests.
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

/// Parse a split name (for `--split`).
pub fn parse_split(s: &str) -> Result<Split, String> {
    match s {
        "train" => Ok(Split::Train),
        "val" => Ok(Split::Val),
        "test" => Ok(Split::Test),
        other => Err(format!("unknown split {other:?} (train, val or test)")),
    }
}
