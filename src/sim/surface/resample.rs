//! Changing the skin resolution (LEMAN 6.5): every per-point value is bilinearly interpolated
//! in material coordinates (periodic around). Per-point masses, damping and spring constants are
//! densities times the point's material area, so they are rescaled by the area ratio; the rest
//! metric, η and ξ are per unit material coordinate and carry over unchanged. Each new free point
//! takes the tissue springs of the nearest old point (anchors unchanged, constants rescaled).

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

use glam::Vec3;

use super::anchors::AnchorTable;
use super::{Core, forces, rest_curvature};

/// Value of a full-grid field (`m` around, `n` along) at continuous grid coordinates `(s, t)`.
fn sample(field: &[f32], m: usize, n: usize, s: f32, t: f32) -> f32 {
    let s = s.rem_euclid(m as f32);
    let t = t.clamp(0.0, (n - 1) as f32);
    let i0 = (s.floor() as usize).min(m - 1);
    let j0 = (t.floor() as usize).min(n - 1);
    let i1 = (i0 + 1) % m;
    let j1 = (j0 + 1).min(n - 1);
    let (fs, ft) = (s - i0 as f32, t - j0 as f32);
    let at = |i: usize, j: usize| field[j * m + i];
    let a = at(i0, j0) + fs * (at(i1, j0) - at(i0, j0));
    let b = at(i0, j1) + fs * (at(i1, j1) - at(i0, j1));
    a + ft * (b - a)
}

/// A free-point field padded to the full grid (fixed rows copy their neighbour row).
fn pad(free_field: &[f32], m: usize, n: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(m * n);
    out.extend_from_slice(&free_field[..m]);
    out.extend_from_slice(free_field);
    out.extend_from_slice(&free_field[free_field.len() - m..]);
    out
}

fn ring_sample(ring: &[Vec3], s: f32) -> Vec3 {
    let m = ring.len();
    let s = s.rem_euclid(m as f32);
    let i0 = (s.floor() as usize).min(m - 1);
    let i1 = (i0 + 1) % m;
    ring[i0].lerp(ring[i1], s - i0 as f32)
}

/// The core resampled to `new_m × new_n`. `rings` are the fixed rows in the world at the current
/// time (row 0 then row N−1, SoA), if known; otherwise those of the neutral posture.
pub(super) fn resample(
    core: &Core,
    new_m: usize,
    new_n: usize,
    rings: Option<[Vec<f32>; 3]>,
) -> Core {
    let (m, n) = (core.around, core.along);
    let rings_known = rings.is_some();
    let rings = rings.unwrap_or_else(|| {
        let r = core.neutral_rings();
        [
            r.iter().map(|p| p.x).collect(),
            r.iter().map(|p| p.y).collect(),
            r.iter().map(|p| p.z).collect(),
        ]
    });
    let mut grid: [Vec<f32>; 3] = Default::default();
    forces::assemble_grid(m, n, &core.x, &rings, &rings, 0.0, &mut grid);
    let free_old = m * (n - 2);
    let free_new = new_m * (new_n - 2);
    let coords = |i: usize, j: usize| {
        (
            i as f32 * m as f32 / new_m as f32,
            j as f32 * (n - 1) as f32 / (new_n - 1) as f32,
        )
    };
    let full = |field: &[f32]| -> Vec<f32> {
        let mut out = Vec::with_capacity(new_m * new_n);
        for j in 0..new_n {
            for i in 0..new_m {
                let (s, t) = coords(i, j);
                out.push(sample(field, m, n, s, t));
            }
        }
        out
    };
    let free_of = |field_free: &[f32], scale: f32| -> Vec<f32> {
        let padded = pad(field_free, m, n);
        let mut out = Vec::with_capacity(free_new);
        for j in 1..new_n - 1 {
            for i in 0..new_m {
                let (s, t) = coords(i, j);
                out.push(sample(&padded, m, n, s, t) * scale);
            }
        }
        out
    };
    let area_ratio = (m * (n - 1)) as f32 / (new_m * (new_n - 1)) as f32;
    let mut x = vec![0.0f32; 3 * free_new];
    let mut v = vec![0.0f32; 3 * free_new];
    let mut rings_world: [Vec<f32>; 3] = Default::default();
    for c in 0..3 {
        let g = full(&grid[c]);
        x[c * free_new..(c + 1) * free_new].copy_from_slice(&g[new_m..new_m + free_new]);
        // The fixed rows as resampled with the grid: what it is drawn with until the next step.
        rings_world[c].extend_from_slice(&g[..new_m]);
        rings_world[c].extend_from_slice(&g[new_m + free_new..]);
        let vc = free_of(&core.v[c * free_old..(c + 1) * free_old], 1.0);
        v[c * free_new..(c + 1) * free_new].copy_from_slice(&vc);
    }
    let mut out = core.clone();
    out.around = new_m;
    out.along = new_n;
    out.x = x;
    out.v = v;
    out.rings_world = if rings_known {
        rings_world
    } else {
        Default::default()
    };
    let mat = &core.materials;
    let three = |f: &[Vec<f32>; 3]| [full(&f[0]), full(&f[1]), full(&f[2])];
    out.materials.eta = three(&mat.eta);
    out.materials.rest_metric = three(&mat.rest_metric);
    out.materials.xi = three(&mat.xi);
    out.materials.mass_kg = free_of(&mat.mass_kg, area_ratio);
    out.materials.damping = free_of(&mat.damping, area_ratio);
    out.materials.fat_m = free_of(&mat.fat_m, 1.0);
    out.materials.inv_mass = out.materials.mass_kg.iter().map(|m| 1.0 / m).collect();
    out.materials.damping_per_mass = out
        .materials
        .damping
        .iter()
        .zip(&out.materials.mass_kg)
        .map(|(d, m)| d / m)
        .collect();
    // Rest curvature from the character's rest shape resampled.
    let rest = {
        let skin = &core.character.skin;
        let rest_grid = [
            skin.positions_m.iter().map(|p| p.x).collect::<Vec<_>>(),
            skin.positions_m.iter().map(|p| p.y).collect(),
            skin.positions_m.iter().map(|p| p.z).collect(),
        ];
        let (sm, sn) = (skin.around as usize, skin.along as usize);
        let mut g: [Vec<f32>; 3] = Default::default();
        for c in 0..3 {
            for j in 0..new_n {
                for i in 0..new_m {
                    let s = i as f32 * sm as f32 / new_m as f32;
                    let t = j as f32 * (sn - 1) as f32 / (new_n - 1) as f32;
                    g[c].push(sample(&rest_grid[c], sm, sn, s, t));
                }
            }
        }
        g
    };
    out.materials.rest_curvature = rest_curvature(new_m, new_n, &rest);
    out.bottom_ring_m = (0..new_m)
        .map(|i| ring_sample(&core.bottom_ring_m, i as f32 * m as f32 / new_m as f32))
        .collect();
    out.top_ring_m = (0..new_m)
        .map(|i| ring_sample(&core.top_ring_m, i as f32 * m as f32 / new_m as f32))
        .collect();
    // Springs: each new free point takes the springs of the nearest old free point.
    let mut by_point: Vec<Vec<usize>> = vec![Vec::new(); free_old];
    for (q, p) in core.springs.point.iter().enumerate() {
        by_point[*p as usize].push(q);
    }
    let s = &core.springs;
    let mut ns = forces::Springs::default();
    for j in 1..new_n - 1 {
        for i in 0..new_m {
            let (fs, ft) = coords(i, j);
            let oi = (fs.round() as usize) % m;
            let oj = (ft.round() as usize).clamp(1, n - 2);
            let old_f = (oj - 1) * m + oi;
            let new_f = ((j - 1) * new_m + i) as u32;
            for &q in &by_point[old_f] {
                ns.point.push(new_f);
                ns.source.push(s.source[q]);
                ns.ks.push(s.ks[q] * area_ratio);
                ns.kd.push(s.kd[q] * area_ratio);
                ns.rest_m.push(s.rest_m[q]);
                ns.shape.push(s.shape[q]);
                ns.anchor_rest_m.push(s.anchor_rest_m[q]);
            }
        }
    }
    // The anchors are placed from a table grouped by shape: it must describe these springs.
    out.anchor_table = AnchorTable::new(&ns, out.character.shapes.len());
    out.springs = ns;
    out
}
