//! Procedural textures (racks, stacked boxes, metal panels, concrete floor, ceiling
//! with lamps) and the pedestrian silhouette, as pure functions of world metres and a
//! hash, so the renderer needs no texture memory besides the sign sprites.

/// A fast 64-bit mix (splitmix64 finaliser).
pub fn hash(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Hash of several integers.
pub fn hash_n(parts: &[i64]) -> u64 {
    parts.iter().fold(0x5151_a5a5_u64, |h, &p| {
        hash(h ^ (p as u64).wrapping_mul(0x2545_f491_4f6c_dd1d))
    })
}

/// Hash of three integers (one mixing round; for per-pixel texture lookups).
#[inline]
pub fn hash3(a: i64, b: i64, c: i64) -> u64 {
    hash(
        (a as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (b as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ (c as u64).wrapping_mul(0x1656_67b1_9e37_79f9),
    )
}

/// `x.floor()` without a libm call (baseline x86-64 has no rounding instruction).
#[inline]
pub fn ffloor(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x { t - 1.0 } else { t }
}

/// `x.rem_euclid(m)` for `m > 0`, without libm calls.
#[inline]
pub fn fmodp(x: f32, m: f32) -> f32 {
    x - ffloor(x / m) * m
}

/// A hash mapped to `[0, 1)`.
pub fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// What a wall face shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WallKind {
    /// Pallet racking with boxes on beams.
    Shelving,
    /// A stack of cardboard boxes.
    Boxes,
    /// Corrugated metal panels with a safety band.
    Panels,
}

impl WallKind {
    /// The kind of a wall face, chosen by hash.
    pub fn of(h: u64) -> WallKind {
        match h % 5 {
            0 | 1 => WallKind::Shelving,
            2 | 3 => WallKind::Boxes,
            _ => WallKind::Panels,
        }
    }
}

const CARDBOARD: [f32; 3] = [0.60, 0.45, 0.29];
const DARK: [f32; 3] = [0.10, 0.10, 0.12];

fn scale(c: [f32; 3], k: f32) -> [f32; 3] {
    [c[0] * k, c[1] * k, c[2] * k]
}

/// Colour of a wall face at `u` metres along it and `z` metres above the floor.
pub fn wall(kind: WallKind, face_hash: u64, u: f32, z: f32) -> [f32; 3] {
    match kind {
        WallKind::Shelving => {
            let bay = 1.5;
            let ub = fmodp(u, bay);
            if ub < 0.08 {
                return [0.16, 0.28, 0.55]; // upright
            }
            let level_h = 1.1;
            let level = ffloor(z / level_h);
            let zl = z - level * level_h;
            if zl < 0.1 {
                return [0.85, 0.43, 0.08]; // beam
            }
            let slot_w = 0.5;
            let slot = ffloor((u - 0.08) / slot_w);
            let us = (u - 0.08) - slot * slot_w;
            let h = hash3(face_hash as i64, level as i64, slot as i64);
            let filled = unit(h) < 0.75;
            let top = 0.1 + (0.45 + 0.5 * unit(hash(h))) * (level_h - 0.1);
            if !filled || zl > top || !(0.03..slot_w - 0.03).contains(&us) {
                return DARK;
            }
            let k = 0.8 + 0.35 * unit(hash(h ^ 7));
            if (zl - top).abs() < 0.02 || us < 0.05 || us > slot_w - 0.05 {
                scale(CARDBOARD, k * 0.7)
            } else {
                scale(CARDBOARD, k)
            }
        }
        WallKind::Boxes => {
            let row_h = 0.45;
            let row = ffloor(z / row_h);
            let zr = z - row * row_h;
            let box_w = 0.6;
            let shift = if (row as i64) % 2 == 0 {
                0.0
            } else {
                box_w / 2.0
            };
            let col = ffloor((u + shift) / box_w);
            let ub = (u + shift) - col * box_w;
            if zr < 0.015 || ub < 0.015 {
                return scale(CARDBOARD, 0.35);
            }
            let h = hash3(face_hash as i64, row as i64, col as i64);
            let k = 0.75 + 0.4 * unit(h);
            let tint = 0.06 * (unit(hash(h)) - 0.5);
            let mut c = [
                CARDBOARD[0] * k + tint,
                CARDBOARD[1] * k,
                CARDBOARD[2] * k - tint,
            ];
            if (ub - box_w / 2.0).abs() < 0.04 {
                c = scale(c, 1.18); // tape
            }
            if unit(hash(h ^ 11)) < 0.2 && (zr - 0.3).abs() < 0.05 && (ub - 0.2).abs() < 0.08 {
                c = [0.9, 0.9, 0.88]; // label
            }
            c
        }
        WallKind::Panels => {
            let seam = fmodp(u, 1.0) < 0.025;
            if seam {
                return [0.3, 0.31, 0.33];
            }
            if (0.95..1.1).contains(&z) {
                return [0.86, 0.7, 0.12]; // safety band
            }
            let ridge = 0.9 + 0.1 * tri(u / 0.12);
            let base = if z < 0.3 {
                0.4
            } else {
                0.6 + 0.04 * unit(face_hash)
            };
            [base * ridge, (base + 0.015) * ridge, (base + 0.035) * ridge]
        }
    }
}

/// A triangle wave in `[-1, 1]` with period 1 (cheaper than a sine, looks alike).
#[inline]
fn tri(x: f32) -> f32 {
    4.0 * (fmodp(x, 1.0) - 0.5).abs() - 1.0
}

/// Concrete floor at world `(x, y)`; `stripe` marks the yellow band along walls.
pub fn floor(x: f32, y: f32, stripe: bool) -> [f32; 3] {
    if stripe {
        return [0.78, 0.66, 0.12];
    }
    let tile = 1.0;
    let (tx, ty) = (ffloor(x / tile), ffloor(y / tile));
    let (fx, fy) = (x - tx * tile, y - ty * tile);
    if fx < 0.015 || fy < 0.015 {
        return [0.3, 0.3, 0.3];
    }
    let h = hash3(tx as i64, ty as i64, 99);
    let speck = unit(hash3((x * 20.0) as i64, (y * 20.0) as i64, 7));
    let v = 0.46 + 0.06 * unit(h) + 0.04 * speck;
    [v, v, v * 0.97]
}

/// Ceiling at world `(x, y)`; `cell` is the cell size. Returns the colour and whether
/// it is a lamp (emissive, not dimmed by distance).
pub fn ceiling(x: f32, y: f32, cell: f32) -> ([f32; 3], bool) {
    let (mx, my) = (fmodp(x, cell), fmodp(y, cell));
    let (fx, fy) = (mx - cell / 2.0, my - cell / 2.0);
    if fx.abs() < 0.25 && fy.abs() < 0.6 {
        return ([0.97, 0.97, 0.92], true);
    }
    let beam = mx < 0.06 || my < 0.06;
    (
        if beam {
            [0.16, 0.16, 0.18]
        } else {
            [0.26, 0.26, 0.28]
        },
        false,
    )
}

/// Pedestrian billboard size `(width, height)` in metres.
pub const PEDESTRIAN_SIZE: (f64, f64) = (0.6, 1.75);

/// The pedestrian silhouette at `(x, z)` metres (x from the body's centre line, z
/// above the floor), walking with phase `phase` (radians). `None` outside the body.
pub fn pedestrian(x: f32, z: f32, phase: f32) -> Option<[f32; 3]> {
    let head = (x * x + (z - 1.62) * (z - 1.62)) < 0.11 * 0.11;
    if head {
        return Some([0.72, 0.55, 0.43]);
    }
    if (0.85..1.5).contains(&z) && x.abs() < 0.2 {
        return Some(if (1.1..1.18).contains(&z) {
            [0.8, 0.8, 0.75]
        } else {
            [0.9, 0.72, 0.1]
        });
    }
    let swing = phase.sin() * 0.07;
    if (0.92..1.46).contains(&z) {
        let arm = 0.2..0.27;
        if arm.contains(&(x - swing * (1.46 - z)).abs()) {
            return Some([0.85, 0.68, 0.1]);
        }
    }
    if z < 0.85 {
        let k = (0.85 - z) / 0.85; // 0 at hip, 1 at foot
        let l = x + 0.08 - swing * k * 1.5;
        let r = x - 0.08 + swing * k * 1.5;
        if l.abs() < 0.065 || r.abs() < 0.065 {
            return Some([0.14, 0.17, 0.3]);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textures_are_deterministic_and_vary() {
        let a = wall(WallKind::Boxes, 3, 0.3, 0.2);
        assert_eq!(a, wall(WallKind::Boxes, 3, 0.3, 0.2));
        let distinct: std::collections::HashSet<[u32; 3]> = (0..40)
            .map(|i| wall(WallKind::Shelving, 5, i as f32 * 0.37, 0.6).map(f32::to_bits))
            .collect();
        assert!(distinct.len() > 3);
        assert!(pedestrian(0.0, 1.62, 0.0).is_some());
        assert!(pedestrian(0.29, 0.1, 0.0).is_none());
        assert!(ceiling(1.5, 1.5, 3.0).1 && !ceiling(0.1, 0.1, 3.0).1);
    }
}
