//! The family's variants: parameter tuples ⟨proposals, block, cell, bins⟩.

use crate::error::{Error, Result};
use crate::hog::HogConfig;
use std::fmt;
use std::str::FromStr;

/// Largest number of pixels a HoG cell is computed from (see [`HogParams::geometry`]).
pub const MAX_CELL_PX: usize = 6;

/// One variant of the feature-based detector: how many EdgeBoxes proposals are
/// classified, and the HoG block size (cells), cell size (pixels) and orientation bins.
///
/// Displayed as the paper writes it, `<1000,2,8,9>`; parsed from that or from
/// `1000,2,8,9`.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct HogParams {
    /// Proposals classified per frame (EdgeBoxes' top `BB`).
    pub proposals: u32,
    /// Block side in cells.
    pub block: u8,
    /// Cell side in pixels.
    pub cell: u8,
    /// Orientation bins over 0-180°.
    pub bins: u8,
}

impl HogParams {
    /// The paper's fixed baseline ⟨1000, 2, 8, 9⟩ (after Alexe et al.).
    pub const BASELINE: HogParams = HogParams {
        proposals: 1000,
        block: 2,
        cell: 8,
        bins: 9,
    };

    /// Every combination of the given values, in lexicographic order
    /// (proposals, block, cell, bins).
    pub fn grid(proposals: &[u32], blocks: &[u8], cells: &[u8], bins: &[u8]) -> Vec<HogParams> {
        let mut out = Vec::new();
        for &p in proposals {
            for &b in blocks {
                for &c in cells {
                    for &n in bins {
                        out.push(HogParams {
                            proposals: p,
                            block: b,
                            cell: c,
                            bins: n,
                        });
                    }
                }
            }
        }
        out
    }

    /// The default grid: proposals {200, 500, 1000, 2000} × block {1, 2} ×
    /// cell {6, 8, 12} × bins {6, 9} — 48 variants sharing 12 HoG configurations;
    /// it contains [`HogParams::BASELINE`].
    pub fn default_grid() -> Vec<HogParams> {
        Self::grid(&[200, 500, 1000, 2000], &[1, 2], &[6, 8, 12], &[6, 9])
    }

    /// The same proposal count with another HoG configuration.
    pub fn with_hog(self, block: u8, cell: u8, bins: u8) -> HogParams {
        HogParams {
            block,
            cell,
            bins,
            ..self
        }
    }

    /// The HoG part of the tuple (what a trained SVM set depends on).
    pub fn hog_key(&self) -> (u8, u8, u8) {
        (self.block, self.cell, self.bins)
    }

    /// Where HoG runs for `window × window` windows: the side a proposal is resampled
    /// to and the HoG settings there.
    ///
    /// The cell grid is the one of `cell`-pixel cells on the window
    /// (`window / cell` cells a side), but a cell is computed from at most
    /// [`MAX_CELL_PX`] pixels: with bigger cells the proposal is resampled to a
    /// proportionally smaller square. The features describe the same grid, and the
    /// pixel work — most of the cost — shrinks with the cell size, which is what
    /// makes cell size a speed knob for the MDP.
    pub fn geometry(&self, window: usize, orientation_interpolation: bool) -> (usize, HogConfig) {
        let cells = window.checked_div(self.cell as usize).unwrap_or(0);
        let px = (self.cell as usize).min(MAX_CELL_PX);
        let cfg = HogConfig {
            cell: px,
            ..self.hog(orientation_interpolation)
        };
        (cells * px, cfg)
    }

    /// The HoG settings of this variant at full resolution (cells of `cell` pixels).
    pub fn hog(&self, orientation_interpolation: bool) -> HogConfig {
        HogConfig {
            cell: self.cell as usize,
            block: self.block as usize,
            bins: self.bins as usize,
            orientation_interpolation,
        }
    }

    /// Check the tuple for `window × window` HoG windows.
    pub fn validate(&self, window: usize) -> Result<()> {
        if self.proposals == 0 {
            return Err(Error::Param {
                name: "proposals",
                reason: "must be at least 1".into(),
            });
        }
        self.hog(false).validate(window)?;
        let (side, cfg) = self.geometry(window, false);
        cfg.validate(side)
    }

    /// Length of the feature vector for `window × window` windows.
    pub fn feature_len(&self, window: usize) -> usize {
        let (side, cfg) = self.geometry(window, false);
        cfg.len(side, side)
    }
}

impl fmt::Display for HogParams {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "<{},{},{},{}>",
            self.proposals, self.block, self.cell, self.bins
        )
    }
}

impl FromStr for HogParams {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let err = |reason: String| Error::ParseParams {
            text: s.to_owned(),
            reason,
        };
        let t = s.trim();
        let t = t.strip_prefix('<').unwrap_or(t);
        let t = t.strip_suffix('>').unwrap_or(t);
        let parts: Vec<&str> = t.split(',').map(str::trim).collect();
        if parts.len() != 4 {
            return Err(err(format!(
                "expected 4 comma-separated numbers (proposals,block,cell,bins), got {}",
                parts.len()
            )));
        }
        let proposals = parts[0]
            .parse::<u32>()
            .map_err(|e| err(format!("proposals {:?}: {e}", parts[0])))?;
        let small = |i: usize, name: &str| {
            parts[i]
                .parse::<u8>()
                .map_err(|e| err(format!("{name} {:?}: {e}", parts[i])))
        };
        Ok(HogParams {
            proposals,
            block: small(1, "block")?,
            cell: small(2, "cell")?,
            bins: small(3, "bins")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_and_parse_round_trip() {
        assert_eq!(HogParams::BASELINE.to_string(), "<1000,2,8,9>");
        assert_eq!(
            "<1000,2,8,9>".parse::<HogParams>().unwrap(),
            HogParams::BASELINE
        );
        assert_eq!(
            " 1000, 2,8 ,9".parse::<HogParams>().unwrap(),
            HogParams::BASELINE
        );
        assert!("1000,2,8".parse::<HogParams>().is_err());
        assert!("1000,2,800,9".parse::<HogParams>().is_err());
        assert!("x,2,8,9".parse::<HogParams>().is_err());
    }

    #[test]
    fn default_grid_holds_the_baseline_and_valid_tuples() {
        let g = HogParams::default_grid();
        assert_eq!(g.len(), 48);
        assert!(g.contains(&HogParams::BASELINE));
        assert!(g.iter().all(|p| p.validate(48).is_ok()));
        assert!(
            HogParams {
                proposals: 0,
                ..HogParams::BASELINE
            }
            .validate(48)
            .is_err()
        );
        // Bigger cells are computed on smaller resamplings, with the same grid.
        let (side, cfg) = HogParams::BASELINE.geometry(48, false);
        assert_eq!((side, cfg.cell), (36, 6));
        assert_eq!(HogParams::BASELINE.feature_len(48), 5 * 5 * 4 * 9);
        assert_eq!(
            HogParams::BASELINE.with_hog(2, 4, 9).geometry(48, false).0,
            48
        );
        assert!(
            HogParams {
                cell: 40,
                ..HogParams::BASELINE
            }
            .validate(48)
            .is_err()
        );
    }
}
