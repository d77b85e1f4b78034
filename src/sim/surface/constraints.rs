//! Non-penetration (LEMAN 4.1.4, 4.2.3): after an accepted integration step every free skin
//! point whose fat point `r − τ n̂` (eq. 6) is inside a muscle is moved out to the muscle's
//! surface (eq. 13a) and its velocity, relative to the muscle's own surface velocity, is split
//! into a normal part reversed and scaled by k∥ and a tangential part scaled by k⊥ (eq. 13b-d;
//! the normal part is only reversed when the point moves into the muscle).
//!
//! # How the pass is organised (speed)
//! The paper found these inside/outside tests to take 77 % of the time. Here the pass is
//! shape-major and works on contiguous arrays so the arithmetic vectorises:
//! - **Broadphase with temporal coherence.** Per shape, the free points that may meet it are
//!   kept as *runs* of consecutive point indices (the skin grid is spatially coherent, so a
//!   muscle meets a few arcs of a few rows). The runs are built from each shape's conservative
//!   box and ellipsoid in its own frame ([`ShapeGeometry::extent_m`],
//!   [`ShapeGeometry::bounding_ellipsoid_m`]), both grown by the largest fat and a margin,
//!   testing only grid rows whose bounding box meets the shape's world box (a two-level
//!   hierarchy). They stay valid while the points' accumulated movement (`max |v|·h`
//!   per step) plus each shape's movement (translation, rotation chord × extent, growth of the
//!   extent) stays below the margin, so no shape can reach a point that is not in its runs.
//! - **Per shape, two stages.** A vectorised loop over the runs maps every fat point into the
//!   shape frame and keeps those inside both the shape's extent box and its bounding
//!   ellipsoid, which cuts off the box's corners (half the box's points on the torso; spheres:
//!   the exact test and projection right there). The survivors form a `Batch` whose values
//!   and gradients are computed by the vectorised kernels (`super::kernels`); points with `F < 0` are
//!   projected by two batched Newton steps along the gradient (a scalar exact projection for
//!   any that do not land within [`PROJECTION_TOLERANCE_M`]), except those whose sign value
//!   alone shows them within half that tolerance of an undeformed shape's surface
//!   (`settled_band`: resting skin the last step left there). The projections become world
//!   moves, push directions and surface velocities in vectorised passes (`super::moves`);
//!   only the writes into the per-point arrays go point by point.
//! - **Rounds.** Shapes are visited in order and each sees the points the earlier ones moved
//!   (Gauss-Seidel); a point pushed out of one muscle into an overlapping one is caught by the
//!   next round, which tests only the points the previous round moved, each against the
//!   shapes other than the one that moved it (at most [`MAX_ROUNDS`], as many as
//!   [`ConstraintInput::rounds`] asks). The skin model's first pass of each step runs one round
//!   and leaves such points to its re-check passes, which run every round. Runs with few points
//!   to test (later rounds, re-checks) are tested point by point instead of over the whole run.

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

use glam::{Affine3A, Vec3};

use super::forces;
use super::kernels::Batch;
use super::masks::collect_hits;
use super::moves::MoveBatch;
use crate::character::{
    PROJECTION_TOLERANCE_M, Primitive, ShapeGeometry, ShapeInstance, within_bounds,
};

/// Rounds over the shapes in one pass (a point pushed into a neighbouring muscle is fixed in
/// the next round).
pub const MAX_ROUNDS: usize = 3;
/// A point whose projection moves it by less than this is already on the surface (the
/// projection tolerance), metres.
const SETTLED_M: f32 = PROJECTION_TOLERANCE_M;
/// Candidate runs closer than this many points (or one grid row, if shorter) are merged. On a
/// 128×128 skin a whole row (the old gap) made the first stage test about 155k points per
/// pass for 28k hits; 16 or 32 points cost 3.6 % fewer instructions in all, 64 points 2.6 %.
const RUN_GAP: usize = 32;
/// Batched Newton steps before the scalar projection takes over.
const NEWTON_STEPS: usize = 2;

/// Candidate runs per shape, their validity bookkeeping, and the pass's scratch arrays.
#[derive(Debug, Clone, Default)]
pub struct Broadphase {
    /// Runs `[start, end)` of free-point indices, all shapes one after another.
    runs: Vec<(u32, u32)>,
    /// Shape `s` owns `runs[run_offsets[s]..run_offsets[s + 1]]`.
    run_offsets: Vec<u32>,
    /// Each shape's frame and extent when the runs were built.
    ref_frames: Vec<Affine3A>,
    ref_extents: Vec<Vec3>,
    /// Each shape's extent this pass.
    extents: Vec<Vec3>,
    /// Each shape's bounding ellipsoid this pass as `1/E²` per axis
    /// ([`ShapeGeometry::bounding_ellipsoid_weights`]).
    ellipsoids: Vec<Vec3>,
    moved_m: f32,
    valid: bool,
    scratch: PassScratch,
    /// Margin, metres: larger means fewer rebuilds and more candidates.
    pub margin_m: f32,
    /// Rebuilds so far (for tests and reports).
    pub rebuilds: u64,
}

/// Per free point: its fat point and the moves a pass made (what a stage's [`MoveLog`]
/// writes).
#[derive(Debug, Clone, Default)]
struct PointMoves {
    /// Fat points, world.
    q: [Vec<f32>; 3],
    /// Round of each point's last move (`u8::MAX`: not moved).
    moved_round: Vec<u8>,
    /// Last shape that moved each point and the direction it moved it (world).
    last_shape: Vec<u32>,
    last_normal: [Vec<f32>; 3],
    /// Velocity of the last moving shape's surface where it left each point (world, m/s,
    /// SoA): eq. 13's reference, taken when the move is recorded.
    surface_vel: [Vec<f32>; 3],
    /// Where the last move left each point's fat point and the direction it moved it, in the
    /// moving shape's own frame (the contact a hold keeps, [`super::contacts`]).
    push_surface: [Vec<f32>; 3],
    push_normal: [Vec<f32>; 3],
    /// Points moved this pass, each once.
    moved: Vec<u32>,
}

/// Per-pass arrays (reused, no allocation in steady state).
#[derive(Debug, Clone, Default)]
struct PassScratch {
    /// The fat points and what the pass did to each.
    points: PointMoves,
    /// Which points the current round tests.
    gate: Vec<u8>,
    /// Per free point: the correction length eq. 13 applied and its largest component, or −1
    /// where none was (scratch of [`apply_moves`]).
    applied_m: Vec<f32>,
    applied_component_m: Vec<f32>,
    /// Per free point, 1 where the pass moved it, and the moved points in index order
    /// (scratch of [`apply_moves`]' sparse path).
    moved_mask: Vec<u8>,
    moved_sorted: Vec<u32>,
    /// Stage-one results along one run (1: a hit), padded to whole words of 8.
    hit: Vec<u8>,
    /// The hits' positions in the run.
    hit_index: Vec<u32>,
    batch: Batch,
    project: Batch,
    /// The world moves of `project`'s entries.
    moves: MoveBatch,
    /// The gated points in ascending order, unless every free point is gated (`all_gated`):
    /// a sparse round (later rounds, re-checks) tests only these.
    gated: Vec<u32>,
    /// `gated_before[f]`: how many gated points are below `f` (`free + 1` entries), so a run's
    /// gated points are a slice found in constant time ([`gated_in`]). Both lists come from the
    /// gate bytes ([`index_gates`]), once per sparse round. Two binary searches per run, done
    /// twice (to pick the runs, then to test them), were about a fifth of `filter_run`'s time
    /// in their dependent compare-and-move chains (replacing them saved about 1 % of the
    /// torso's wall time).
    gated_before: Vec<u32>,
    /// Every free point is gated (the first round of a full pass).
    all_gated: bool,
    /// The runs of one shape that hold gated points.
    active_runs: Vec<(u32, u32)>,
    /// Original shape-space positions of `project`'s entries (SoA).
    origin: [Vec<f32>; 3],
    /// All ones, per free point (the rebuild's filters test every point).
    ones: Vec<u8>,
    /// Grid-row boxes (rebuild).
    row_lo: Vec<Vec3>,
    row_hi: Vec<Vec3>,
}

impl Broadphase {
    /// Forces a rebuild at the next pass (after a restore, a resolution or fat change).
    pub fn invalidate(&mut self) {
        self.valid = false;
    }

    /// Sets `mask[f] = 1` for every free point the last [`enforce`] call moved.
    pub fn mark_moved(&self, mask: &mut [u8]) {
        for &f in &self.scratch.points.moved {
            if let Some(m) = mask.get_mut(f as usize) {
                *m = 1;
            }
        }
    }

    /// Per free point, the last push the passes recorded (valid for the points a pass of the
    /// current phase moved, [`Self::mark_moved`]) and the fat points as the last pass left them.
    pub fn pushes(&self) -> Pushes<'_> {
        let p = &self.scratch.points;
        Pushes {
            shape: &p.last_shape,
            normal: &p.last_normal,
            surface_shape: &p.push_surface,
            normal_shape: &p.push_normal,
            fat_points: &p.q,
        }
    }
}

/// Per free point, the last push the constraint passes recorded, and the fat points (see
/// [`Broadphase::pushes`]).
#[derive(Debug, Clone, Copy)]
pub struct Pushes<'a> {
    /// Index of the shape that pushed the point last.
    pub shape: &'a [u32],
    /// The direction it pushed it in (its outward unit normal there), world (SoA).
    pub normal: &'a [Vec<f32>; 3],
    /// Where the push left the fat point, in that shape's frame, metres (SoA).
    pub surface_shape: &'a [Vec<f32>; 3],
    /// The push direction in that shape's frame (SoA).
    pub normal_shape: &'a [Vec<f32>; 3],
    /// The fat points as the last pass left them, world, metres (SoA).
    pub fat_points: &'a [Vec<f32>; 3],
}

/// What a constraint pass found.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ConstraintOutcome {
    /// Largest position component correction, metres (compared with ε_c).
    pub max_component_m: f32,
    /// Largest correction length, metres.
    pub max_correction_m: f32,
    /// Points moved.
    pub corrected: u32,
    /// Free point with the largest correction, and the last shape that moved it.
    pub worst: (u32, u32),
}

/// Inputs of a constraint pass.
pub struct ConstraintInput<'a> {
    /// M.
    pub around: usize,
    /// N.
    pub along: usize,
    /// Shapes at the end of the step.
    pub shapes_end: &'a [ShapeInstance],
    /// Shapes at the start of the step (for the muscles' surface velocity).
    pub shapes_start: &'a [ShapeInstance],
    /// Step length, seconds.
    pub h_s: f32,
    /// Fat per free point, m.
    pub fat_m: &'a [f32],
    /// Largest fat, m.
    pub max_fat_m: f32,
    /// k∥.
    pub k_parallel: f32,
    /// k⊥.
    pub k_perpendicular: f32,
    /// Largest speed of any point in the candidate state (bounds its movement this step).
    pub max_speed_m_per_s: f32,
    /// Corrections longer than this mark a point's neighbourhood for a re-check, metres.
    pub recheck_m: f32,
    /// Gauss-Seidel rounds over the shapes (at most [`MAX_ROUNDS`]).
    pub rounds: usize,
}

/// How far the rotation from frame `a` to frame `b` moves a point at unit distance from the
/// frames' origin, metres per metre: the chord `2 sin(θ/2) = √(3 − tr(R_b R_aᵀ))` of the
/// rotation angle `θ`. This is the exact largest displacement (no larger than the arc `θ`,
/// which this bound used to be), and needs a square root where the angle needed an `acos`.
fn rotation_chord(a: &Affine3A, b: &Affine3A) -> f32 {
    let (ma, mb) = (a.matrix3, b.matrix3);
    let trace = ma.x_axis.dot(mb.x_axis) + ma.y_axis.dot(mb.y_axis) + ma.z_axis.dot(mb.z_axis);
    (3.0 - trace).max(0.0).sqrt()
}

impl Broadphase {
    fn update(&mut self, input: &ConstraintInput<'_>, grid: &[Vec<f32>; 3]) {
        let shapes = input.shapes_end;
        let free = input.around * (input.along - 2);
        self.moved_m += input.max_speed_m_per_s * input.h_s;
        self.extents.clear();
        self.extents
            .extend(shapes.iter().map(|s| s.geometry.extent_m()));
        self.ellipsoids.clear();
        self.ellipsoids
            .extend(shapes.iter().map(|s| match s.geometry.primitive {
                // The sphere stage's test is exact and needs no bound.
                Primitive::Sphere { .. } if s.geometry.is_undeformed() => Vec3::ZERO,
                _ => s.geometry.bounding_ellipsoid_weights(),
            }));
        let mut shape_moved = 0.0f32;
        if self.ref_frames.len() == shapes.len() {
            for (k, s) in shapes.iter().enumerate() {
                let (was, now) = (&self.ref_frames[k], &s.world_from_shape);
                let (e_was, e_now) = (self.ref_extents[k], self.extents[k]);
                let d = (Vec3::from(now.translation) - Vec3::from(was.translation)).length()
                    + rotation_chord(was, now) * e_was.length().max(e_now.length())
                    + (e_now - e_was).max(Vec3::ZERO).max_element();
                shape_moved = shape_moved.max(d);
            }
        } else {
            self.valid = false;
        }
        let sized = self.scratch.gate.len() == free && self.run_offsets.len() == shapes.len() + 1;
        if self.valid && sized && self.moved_m + shape_moved <= self.margin_m {
            return;
        }
        self.rebuild(input, grid);
    }

    fn rebuild(&mut self, input: &ConstraintInput<'_>, grid: &[Vec<f32>; 3]) {
        let shapes = input.shapes_end;
        let m = input.around;
        let rows = input.along - 2;
        let free = m * rows;
        self.rebuilds += 1;
        self.valid = true;
        self.moved_m = 0.0;
        self.ref_frames.clear();
        self.ref_frames
            .extend(shapes.iter().map(|s| s.world_from_shape));
        self.ref_extents.clone_from(&self.extents);
        let sc = &mut self.scratch;
        sc.gate.resize(free, 0);
        sc.points.moved_round.resize(free, u8::MAX);
        sc.points.last_shape.resize(free, 0);
        for c in sc
            .points
            .last_normal
            .iter_mut()
            .chain(&mut sc.points.surface_vel)
            .chain(&mut sc.points.push_surface)
            .chain(&mut sc.points.push_normal)
        {
            c.resize(free, 0.0);
        }
        sc.ones.resize(free, 1);
        for c in &mut sc.points.q {
            c.resize(free, 0.0);
        }
        // Row boxes.
        sc.row_lo.clear();
        sc.row_hi.clear();
        for r in 0..rows {
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for i in 0..m {
                let k = m + r * m + i;
                let p = Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
                lo = lo.min(p);
                hi = hi.max(p);
            }
            sc.row_lo.push(lo);
            sc.row_hi.push(hi);
        }
        let grow = input.max_fat_m + self.margin_m;
        // Runs separated by less than a row (at most RUN_GAP points) are merged: the first
        // stage is a vectorised loop, so testing some extra points costs less than another run.
        let run_gap = m.min(RUN_GAP) as u32;
        self.runs.clear();
        self.run_offsets.clear();
        self.run_offsets.push(0);
        for ((s, extent), w) in shapes.iter().zip(&self.extents).zip(&self.ellipsoids) {
            let reach = *extent + Vec3::splat(grow);
            let center = Vec3::from(s.world_from_shape.translation);
            let mat = s.world_from_shape.matrix3;
            // World half-extents of the grown box: Σ_j |R_ij| reach_j.
            let half = Vec3::from(
                mat.x_axis.abs() * reach.x
                    + mat.y_axis.abs() * reach.y
                    + mat.z_axis.abs() * reach.z,
            );
            let (lo, hi) = (center - half, center + half);
            let sphere_reach = match s.geometry.primitive {
                Primitive::Sphere { radius_m } if s.geometry.is_undeformed() => {
                    Some(radius_m + grow)
                }
                _ => None,
            };
            // The rows whose boxes meet the shape's world box, tested as one vectorised span (a
            // row in between that misses the box has no point in it either). Points strictly
            // inside the sphere's reach or in the box's reach are candidates.
            let overlapping =
                |r: &usize| !(sc.row_lo[*r].cmpgt(hi).any() || sc.row_hi[*r].cmplt(lo).any());
            let span = (0..rows)
                .find(overlapping)
                .zip((0..rows).rev().find(overlapping));
            if let Some((r0, r1)) = span {
                let (a, b) = (r0 * m, (r1 + 1) * m);
                let len = b - a;
                sc.hit.resize(len.next_multiple_of(8), 0);
                let (gx, gy, gz) = (
                    &grid[0][m + a..m + b],
                    &grid[1][m + a..m + b],
                    &grid[2][m + a..m + b],
                );
                let (ones, hit) = (&sc.ones[a..b], &mut sc.hit[..len]);
                match sphere_reach {
                    Some(r) => sphere_filter(center, r * r, gx, gy, gz, ones, hit),
                    // The ellipsoid `E` grown by `g` is inside `(1 + g/E_min) E` (a ball of
                    // radius `g` is inside `(g/E_min) E`).
                    None => {
                        let e_min = w.max_element().sqrt().recip();
                        let grown = *w / (1.0 + grow / e_min).powi(2);
                        box_filter(&s.shape_from_world, reach, grown, [gx, gy, gz], ones, hit)
                    }
                }
                sc.hit[len..].fill(0);
                collect_hits(&sc.hit, &mut sc.hit_index);
                // The shape's runs: a new one where the next hit is more than `run_gap`
                // past the end of the current one.
                if let Some((&i0, hits)) = sc.hit_index.split_first() {
                    let (mut start, mut end) = (a as u32 + i0, a as u32 + i0 + 1);
                    for &i in hits {
                        let f = a as u32 + i;
                        if f > end + run_gap {
                            self.runs.push((start, end));
                            start = f;
                        }
                        end = f + 1;
                    }
                    self.runs.push((start, end));
                }
            }
            self.run_offsets.push(self.runs.len() as u32);
        }
    }
}

/// Applies the constraints to a candidate state in place. `grid` must hold the full grid of the
/// candidate positions and `normals` its normals (a re-check reads only those of the points in
/// `only`). The free points of `x`, `v` and the grid are updated together. `only` restricts the
/// pass to those free points (a re-check); the points moved by more than `input.recheck_m` are
/// written to `touched`.
#[allow(clippy::too_many_arguments)]
pub fn enforce(
    input: &ConstraintInput<'_>,
    broad: &mut Broadphase,
    grid: &mut [Vec<f32>; 3],
    normals: &[Vec<f32>; 3],
    x: &mut [f32],
    v: &mut [f32],
    only: Option<&[u32]>,
    touched: &mut Vec<u32>,
) -> ConstraintOutcome {
    let shapes = input.shapes_end;
    if only.is_none()
        || broad.run_offsets.len() != shapes.len() + 1
        || broad.scratch.gate.len() != input.around * (input.along - 2)
    {
        broad.update(input, grid);
    }
    let m = input.around;
    let free = m * (input.along - 2);
    let sc = &mut broad.scratch;
    touched.clear();
    let inv_h = if input.h_s > 0.0 {
        1.0 / input.h_s
    } else {
        0.0
    };
    // Fat points r − τ n̂.
    for c in 0..3 {
        fat_points(
            &grid[c][m..m + free],
            &normals[c][m..m + free],
            &input.fat_m[..free],
            &mut sc.points.q[c][..free],
        );
    }
    match only {
        None => sc.gate.fill(1),
        Some(list) => {
            sc.gate.fill(0);
            for &f in list {
                if let Some(g) = sc.gate.get_mut(f as usize) {
                    *g = 1;
                }
            }
        }
    }
    sc.all_gated = only.is_none();
    sc.points.moved_round.fill(u8::MAX);
    sc.points.moved.clear();
    for round in 0..input.rounds.min(MAX_ROUNDS) {
        if round > 0 {
            let previous = (round - 1) as u8;
            // Only the points moved in the previous round are gated now.
            for (g, r) in sc.gate.iter_mut().zip(&sc.points.moved_round) {
                *g = u8::from(*r == previous);
            }
            sc.all_gated = false;
        }
        let mut changed = 0usize;
        let everyone = sc.all_gated;
        if !everyone {
            index_gates(&sc.gate, &mut sc.gated, &mut sc.gated_before);
            if sc.gated.is_empty() {
                break;
            }
        }
        for (s_idx, s) in shapes.iter().enumerate() {
            let (a, b) = (
                broad.run_offsets[s_idx] as usize,
                broad.run_offsets[s_idx + 1] as usize,
            );
            let mut active = std::mem::take(&mut sc.active_runs);
            let runs: &[(u32, u32)] = if everyone {
                &broad.runs[a..b]
            } else {
                active.clear();
                let before = &sc.gated_before;
                active.extend(
                    broad.runs[a..b]
                        .iter()
                        .copied()
                        .filter(|&(a, b)| before[a as usize] < before[b as usize]),
                );
                &active
            };
            if !runs.is_empty() {
                let owed = Owed {
                    shape: s_idx as u32,
                    round: round as u8,
                };
                let motion = SurfaceMotion {
                    start: input
                        .shapes_start
                        .get(s_idx)
                        .filter(|_| input.shapes_start.len() == shapes.len()),
                    inv_h,
                };
                changed += match s.geometry.primitive {
                    Primitive::Sphere { radius_m } if s.geometry.is_undeformed() => {
                        sphere_stage(sc, runs, s, owed, motion, radius_m)
                    }
                    _ => {
                        let bound = (broad.extents[s_idx], broad.ellipsoids[s_idx]);
                        general_stage(sc, runs, s, owed, motion, bound)
                    }
                };
            }
            sc.active_runs = active;
        }
        if changed == 0 {
            break;
        }
    }
    apply_moves(input, sc, grid, normals, x, v, touched)
}

crate::sim::simd::multiversion! {
    /// One component of the fat points `q = r − τ n̂` (eq. 6) from the skin points' `g`, their
    /// normals' `n` and the fat `τ`. (As an index loop over the four arrays the compiler kept
    /// it scalar: about 8 % of a re-check's instructions.)
    fn fat_points(g: &[f32], n: &[f32], fat: &[f32], q: &mut [f32]) {
        let len = q.len().min(g.len()).min(n.len()).min(fat.len());
        let (g, n, fat, q) = (&g[..len], &n[..len], &fat[..len], &mut q[..len]);
        for f in 0..len {
            q[f] = g[f] - n[f] * fat[f];
        }
    }
}

/// Moves each skin point whose fat point the pass moved so that its fat point is where the
/// pass left it (eq. 13a), and sets its velocity by eq. 13b-d relative to the surface of the
/// shape that moved it last (its velocity there was taken when the move was recorded). One
/// vectorised pass over every free point with the unmoved ones masked out (most points move
/// in a pass of resting skin), then a scan of the applied lengths for the report, in index
/// order. The points moved by more than `input.recheck_m` go to `touched`.
fn apply_moves(
    input: &ConstraintInput<'_>,
    sc: &mut PassScratch,
    grid: &mut [Vec<f32>; 3],
    normals: &[Vec<f32>; 3],
    x: &mut [f32],
    v: &mut [f32],
    touched: &mut Vec<u32>,
) -> ConstraintOutcome {
    let m = input.around;
    let free = m * (input.along - 2);
    let mut out = ConstraintOutcome::default();
    let [g0, g1, g2] = grid;
    let [n0, n1, n2] = normals;
    let [x0, x1, x2] = forces::blocks_mut(x, free);
    let [v0, v1, v2] = forces::blocks_mut(v, free);
    let [q0, q1, q2] = &sc.points.q;
    let fat = &input.fat_m[..free];
    // The points eq. 13 moved, in index order, into the outcome.
    let recheck_m = input.recheck_m;
    let mut report = |f: usize, len: f32, component: f32| {
        out.report(
            f,
            len,
            component,
            sc.points.last_shape[f],
            recheck_m,
            touched,
        );
    };
    if sc.points.moved.len() * DENSE_MOVES < free {
        // Few moved points (re-checks): point by point, in index order, the same arithmetic.
        // The order comes from a scan of the moved rounds rather than a sort of the moved
        // list (each point is on it once, so both give the same ascending list): sorting the
        // re-checks' 50-250 points was about 1 % of the torso's time, in mispredicted
        // comparisons, where the scan is a vectorised compare and a word-wise hit list.
        let mut order = std::mem::take(&mut sc.moved_sorted);
        let mask = &mut sc.moved_mask;
        mask.clear();
        mask.extend(
            sc.points.moved_round[..free]
                .iter()
                .map(|&r| u8::from(r != u8::MAX)),
        );
        collect_hits(mask, &mut order);
        debug_assert_eq!(order.len(), sc.points.moved.len());
        let (g, n, [s0, s1, s2], [l0, l1, l2]) = (
            [g0, g1, g2],
            [n0, n1, n2],
            &sc.points.surface_vel,
            &sc.points.last_normal,
        );
        for &f in &order {
            let f = f as usize;
            let k = m + f;
            let (p, len, component) = eq13_position(
                [q0[f], q1[f], q2[f]],
                [n[0][k], n[1][k], n[2][k]],
                fat[f],
                [g[0][k], g[1][k], g[2][k]],
            );
            if len.is_nan() || len <= 0.0 {
                continue;
            }
            (g[0][k], g[1][k], g[2][k]) = (p[0], p[1], p[2]);
            (x0[f], x1[f], x2[f]) = (p[0], p[1], p[2]);
            let w = eq13_velocity(
                [v0[f], v1[f], v2[f]],
                [s0[f], s1[f], s2[f]],
                [l0[f], l1[f], l2[f]],
                input.k_parallel,
                input.k_perpendicular,
            );
            (v0[f], v1[f], v2[f]) = (w[0], w[1], w[2]);
            report(f, len, component);
        }
        sc.moved_sorted = order;
        return out;
    }
    sc.applied_m.resize(free, -1.0);
    sc.applied_component_m.resize(free, -1.0);
    eq13_positions(
        &sc.points.moved_round[..free],
        &q0[..free],
        &q1[..free],
        &q2[..free],
        &n0[m..m + free],
        &n1[m..m + free],
        &n2[m..m + free],
        fat,
        &mut g0[m..m + free],
        &mut g1[m..m + free],
        &mut g2[m..m + free],
        x0,
        x1,
        x2,
        &mut sc.applied_m[..free],
        &mut sc.applied_component_m[..free],
    );
    let ([s0, s1, s2], [l0, l1, l2]) = (&sc.points.surface_vel, &sc.points.last_normal);
    eq13_velocities(
        &sc.applied_m[..free],
        &s0[..free],
        &s1[..free],
        &s2[..free],
        &l0[..free],
        &l1[..free],
        &l2[..free],
        input.k_parallel,
        input.k_perpendicular,
        v0,
        v1,
        v2,
    );
    out.report_all(
        &sc.applied_m[..free],
        &sc.applied_component_m[..free],
        &sc.points.last_shape,
        recheck_m,
        touched,
    );
    out
}

/// [`moves_summary`]'s result: what the dense [`apply_moves`] reports about its moves.
struct MovesSummary {
    /// Points moved (`applied ≥ 0`).
    moved: u32,
    /// Largest correction length, metres (0 when nothing moved).
    max_correction_m: f32,
    /// Largest correction component, metres (0 when nothing moved).
    max_component_m: f32,
}

crate::sim::simd::multiversion! {
    /// The count and maxima of [`eq13_positions`]' output (`applied` and `component` are −1
    /// where nothing moved and positive where a point did), in independent lanes so the loop
    /// vectorises. An infinite correction comes out infinite, as it did from the scan.
    fn moves_summary(applied: &[f32], component: &[f32]) -> MovesSummary {
        use crate::sim::simd::LANES;
        #[inline(always)]
        fn take(
            l: usize,
            len: f32,
            comp: f32,
            moved: &mut [u32; LANES],
            max_len: &mut [f32; LANES],
            max_comp: &mut [f32; LANES],
        ) {
            moved[l] += u32::from(len >= 0.0);
            max_len[l] = if len > max_len[l] { len } else { max_len[l] };
            max_comp[l] = if comp > max_comp[l] { comp } else { max_comp[l] };
        }
        let mut moved = [0u32; LANES];
        let mut max_len = [0f32; LANES];
        let mut max_comp = [0f32; LANES];
        let n = applied.len().min(component.len());
        let (ac, ar) = applied[..n].as_chunks::<LANES>();
        let (cc, cr) = component[..n].as_chunks::<LANES>();
        for (a, c) in ac.iter().zip(cc) {
            for l in 0..LANES {
                take(l, a[l], c[l], &mut moved, &mut max_len, &mut max_comp);
            }
        }
        for (l, (&a, &c)) in ar.iter().zip(cr).enumerate() {
            take(l, a, c, &mut moved, &mut max_len, &mut max_comp);
        }
        MovesSummary {
            moved: moved.iter().sum(),
            max_correction_m: max_len.iter().fold(0.0, |m, &d| if d > m { d } else { m }),
            max_component_m: max_comp.iter().fold(0.0, |m, &d| if d > m { d } else { m }),
        }
    }
}

/// [`apply_moves`] runs its vectorised passes over every free point when at least one in this
/// many moved (a first pass over resting skin moves two of three), and visits the moved points
/// one by one otherwise (a re-check moves a few dozen).
const DENSE_MOVES: usize = 4;

impl ConstraintOutcome {
    /// Takes in a correction of length `len` (and largest component `component`, metres) that
    /// eq. 13 applied to free point `f`, last moved by shape `shape`; the points are reported
    /// in index order. A correction longer than `recheck_m` puts the point in `touched`.
    #[inline(always)]
    fn report(
        &mut self,
        f: usize,
        len: f32,
        component: f32,
        shape: u32,
        recheck_m: f32,
        touched: &mut Vec<u32>,
    ) {
        self.max_component_m = self.max_component_m.max(component);
        if len > self.max_correction_m {
            self.max_correction_m = len;
            self.worst = (f as u32, shape);
        }
        self.corrected += 1;
        if len > recheck_m {
            touched.push(f as u32);
        }
    }

    /// [`Self::report`] for every free point at once: `applied` and `component` as
    /// [`eq13_positions`] left them (−1 where nothing moved), `last_shape` per free point.
    /// The same outcome and `touched` list as reporting the moved points one by one in index
    /// order, without a branch per point: which points moved is scattered, and a scan branching
    /// on it mispredicted often enough to take about a quarter of `enforce`'s own profile
    /// samples on the penguin.
    fn report_all(
        &mut self,
        applied: &[f32],
        component: &[f32],
        last_shape: &[u32],
        recheck_m: f32,
        touched: &mut Vec<u32>,
    ) {
        let summary = moves_summary(applied, component);
        self.corrected += summary.moved;
        self.max_component_m = self.max_component_m.max(summary.max_component_m);
        if summary.max_correction_m > self.max_correction_m {
            // The first point with the largest correction, as `report`'s strict `>` keeps.
            if let Some(f) = applied
                .iter()
                .position(|&len| len == summary.max_correction_m)
            {
                self.max_correction_m = summary.max_correction_m;
                self.worst = (f as u32, last_shape[f]);
            }
        }
        let start = touched.len();
        touched.resize(start + applied.len(), 0);
        let mut listed = start;
        for (f, &len) in applied.iter().enumerate() {
            touched[listed] = f as u32;
            listed += usize::from(len > recheck_m);
        }
        touched.truncate(listed);
    }
}

/// Eq. 13a for one point: the skin point `q + τ n` for the fat point `q` the pass left, the
/// length of its correction from `p0` and that correction's largest component (metres).
#[inline(always)]
fn eq13_position(q: [f32; 3], n: [f32; 3], fat: f32, p0: [f32; 3]) -> ([f32; 3], f32, f32) {
    let p = [q[0] + n[0] * fat, q[1] + n[1] * fat, q[2] + n[2] * fat];
    let (dx, dy, dz) = (p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]);
    let len = (dx * dx + dy * dy + dz * dz).sqrt();
    (p, len, dx.abs().max(dy.abs()).max(dz.abs()))
}

/// Eq. 13b-d for one point: the velocity `v` relative to the muscle surface's `s`, its part
/// along the unit normal `l` reversed and scaled by k∥ if it points into the muscle (kept
/// otherwise), the tangential part scaled by k⊥.
#[inline(always)]
fn eq13_velocity(v: [f32; 3], s: [f32; 3], l: [f32; 3], k_par: f32, k_perp: f32) -> [f32; 3] {
    let (rx, ry, rz) = (v[0] - s[0], v[1] - s[1], v[2] - s[2]);
    let vn = rx * l[0] + ry * l[1] + rz * l[2];
    let (nx, ny, nz) = (l[0] * vn, l[1] * vn, l[2] * vn);
    let (tx, ty, tz) = (rx - nx, ry - ny, rz - nz);
    let (ax, ay, az) = if vn < 0.0 {
        (-k_par * nx, -k_par * ny, -k_par * nz)
    } else {
        (nx, ny, nz)
    };
    [
        s[0] + ax + k_perp * tx,
        s[1] + ay + k_perp * ty,
        s[2] + az + k_perp * tz,
    ]
}

crate::sim::simd::multiversion! {
    /// [`apply_moves`]' positions (eq. 13a) for every free point: where `moved_round` marks a
    /// move and the correction `d = (q + τ n) − p` (`p` the grid point) has a length `> 0`, the
    /// point (`g`, `x`) goes to `q + τ n`, `applied` gets `|d|` and `component` `max_i |d_i|`;
    /// elsewhere nothing moves and both get −1. Every slice is its own argument, so the
    /// compiler knows they do not overlap and vectorises the loop.
    fn eq13_positions(
        moved_round: &[u8],
        q0: &[f32],
        q1: &[f32],
        q2: &[f32],
        n0: &[f32],
        n1: &[f32],
        n2: &[f32],
        fat: &[f32],
        g0: &mut [f32],
        g1: &mut [f32],
        g2: &mut [f32],
        x0: &mut [f32],
        x1: &mut [f32],
        x2: &mut [f32],
        applied: &mut [f32],
        component: &mut [f32],
    ) {
        let len = moved_round.len().min(fat.len()).min(applied.len()).min(component.len());
        let (moved_round, fat) = (&moved_round[..len], &fat[..len]);
        let (q0, q1, q2) = (&q0[..len], &q1[..len], &q2[..len]);
        let (n0, n1, n2) = (&n0[..len], &n1[..len], &n2[..len]);
        let (g0, g1, g2) = (&mut g0[..len], &mut g1[..len], &mut g2[..len]);
        let (x0, x1, x2) = (&mut x0[..len], &mut x1[..len], &mut x2[..len]);
        let (applied, component) = (&mut applied[..len], &mut component[..len]);
        for f in 0..len {
            let (p, d_len, largest) = eq13_position(
                [q0[f], q1[f], q2[f]],
                [n0[f], n1[f], n2[f]],
                fat[f],
                [g0[f], g1[f], g2[f]],
            );
            // Not moved, or a correction of zero or NaN length: nothing changes.
            let ok = (moved_round[f] != u8::MAX) & (d_len > 0.0);
            applied[f] = if ok { d_len } else { -1.0 };
            component[f] = if ok { largest } else { -1.0 };
            g0[f] = if ok { p[0] } else { g0[f] };
            g1[f] = if ok { p[1] } else { g1[f] };
            g2[f] = if ok { p[2] } else { g2[f] };
            x0[f] = if ok { p[0] } else { x0[f] };
            x1[f] = if ok { p[1] } else { x1[f] };
            x2[f] = if ok { p[2] } else { x2[f] };
        }
    }
}

crate::sim::simd::multiversion! {
    /// [`apply_moves`]' velocities (eq. 13b-d) where `applied ≥ 0`: relative to the muscle
    /// surface's velocity `s`, the normal part along the unit `l` is reversed and scaled by
    /// k∥ if it points into the muscle (kept otherwise), the tangential part scaled by k⊥.
    fn eq13_velocities(
        applied: &[f32],
        s0: &[f32],
        s1: &[f32],
        s2: &[f32],
        l0: &[f32],
        l1: &[f32],
        l2: &[f32],
        k_parallel: f32,
        k_perpendicular: f32,
        v0: &mut [f32],
        v1: &mut [f32],
        v2: &mut [f32],
    ) {
        let len = applied.len();
        let (s0, s1, s2) = (&s0[..len], &s1[..len], &s2[..len]);
        let (l0, l1, l2) = (&l0[..len], &l1[..len], &l2[..len]);
        let (v0, v1, v2) = (&mut v0[..len], &mut v1[..len], &mut v2[..len]);
        for f in 0..len {
            let ok = applied[f] >= 0.0;
            let w = eq13_velocity(
                [v0[f], v1[f], v2[f]],
                [s0[f], s1[f], s2[f]],
                [l0[f], l1[f], l2[f]],
                k_parallel,
                k_perpendicular,
            );
            v0[f] = if ok { w[0] } else { v0[f] };
            v1[f] = if ok { w[1] } else { v1[f] };
            v2[f] = if ok { w[2] } else { v2[f] };
        }
    }
}

/// How the surface of the shape taking its turn (the step's end instance, which the stage
/// holds) moved over the step, for eq. 13's relative velocity.
#[derive(Clone, Copy)]
struct SurfaceMotion<'a> {
    /// The same shape at the start of the step; `None` when the step's shapes differ (a
    /// character edit), and the surface then counts as still.
    start: Option<&'a ShapeInstance>,
    /// 1 / step length, 1/s (0 for an empty step).
    inv_h: f32,
}

impl SurfaceMotion<'_> {
    /// Velocity of the surface point now at `q` (world), whose place in the shape's frame at
    /// the end of the step is `local` (the caller has it already): it was at
    /// `start.world_from_shape(local)` at the start of the step.
    #[inline]
    fn velocity_at(&self, q: Vec3, local: Vec3) -> Vec3 {
        match self.start {
            Some(start) => (q - start.world_from_shape.transform_point3(local)) * self.inv_h,
            None => Vec3::ZERO,
        }
    }
}

/// The [`PointMoves`] arrays a stage records its moves in, each borrowed as a slice over the
/// free points: one length for all (so one bounds check per move), held in registers across
/// the pushes onto `moved` (writes through a `&mut PassScratch` made the compiler reload every
/// array after each push: 1.5 % of the torso's instructions, 4 % of the penguin's).
struct MoveLog<'a> {
    q: [&'a mut [f32]; 3],
    surface_vel: [&'a mut [f32]; 3],
    last_normal: [&'a mut [f32]; 3],
    push_surface: [&'a mut [f32]; 3],
    push_normal: [&'a mut [f32]; 3],
    moved_round: &'a mut [u8],
    last_shape: &'a mut [u32],
    moved: &'a mut Vec<u32>,
}

impl<'a> MoveLog<'a> {
    #[inline(always)]
    fn new(points: &'a mut PointMoves) -> Self {
        let PointMoves {
            q,
            moved_round,
            last_shape,
            last_normal,
            surface_vel,
            push_surface,
            push_normal,
            moved,
        } = points;
        // The shortest array's length, as a plain minimum (a chain of iterators over the five
        // triples stayed a called fold: about 1 % of the torso's time, the stages making a
        // log per run).
        let min3 = |a: &[Vec<f32>; 3]| a[0].len().min(a[1].len()).min(a[2].len());
        let n = (min3(q).min(min3(surface_vel)).min(min3(last_normal)))
            .min(min3(push_surface).min(min3(push_normal)))
            .min(moved_round.len().min(last_shape.len()));
        let cut = |[x, y, z]: &'a mut [Vec<f32>; 3]| [&mut x[..n], &mut y[..n], &mut z[..n]];
        MoveLog {
            q: cut(q),
            surface_vel: cut(surface_vel),
            last_normal: cut(last_normal),
            push_surface: cut(push_surface),
            push_normal: cut(push_normal),
            moved_round: &mut moved_round[..n],
            last_shape: &mut last_shape[..n],
            moved,
        }
    }

    /// Records that `f`'s fat point was moved to `q` (world, along the unit `normal`; `local`
    /// and `local_normal` are the same in the moving shape's frame) by `by`'s shape in its
    /// round, where that shape's surface moves at `surface` (m/s; eq. 13's reference,
    /// [`SurfaceMotion::velocity_at`]).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)] // the move, in both frames
    fn record(
        &mut self,
        f: usize,
        q: Vec3,
        surface: Vec3,
        normal: Vec3,
        local: Vec3,
        local_normal: Vec3,
        by: Owed,
    ) {
        for c in 0..3 {
            self.q[c][f] = q[c];
            self.surface_vel[c][f] = surface[c];
            self.last_normal[c][f] = normal[c];
            self.push_surface[c][f] = local[c];
            self.push_normal[c][f] = local_normal[c];
        }
        if self.moved_round[f] == u8::MAX {
            self.moved.push(f as u32);
        }
        self.moved_round[f] = by.round;
        self.last_shape[f] = by.shape;
    }
}

/// An undeformed sphere: exact test and projection over the runs. Returns the points moved.
fn sphere_stage(
    sc: &mut PassScratch,
    runs: &[(u32, u32)],
    s: &ShapeInstance,
    owed: Owed,
    motion: SurfaceMotion<'_>,
    radius_m: f32,
) -> usize {
    let c = Vec3::from(s.world_from_shape.translation);
    let r2 = radius_m * radius_m;
    let mut moved = 0;
    for &(a, b) in runs {
        let (a, b) = (a as usize, b as usize);
        let filter = Filter::Sphere { center: c, r2 };
        filter_run(sc, a, b, filter, owed);
        let found = std::mem::take(&mut sc.hit_index);
        let mut log = MoveLog::new(&mut sc.points);
        for &i in &found {
            let f = a + i as usize;
            let q = Vec3::new(log.q[0][f], log.q[1][f], log.q[2][f]);
            let d = q - c;
            let dist = d.length();
            let dir = if dist > 1e-12 {
                d / dist
            } else {
                s.world_from_shape.matrix3.y_axis.into()
            };
            let target = c + dir * radius_m;
            let delta = target - q;
            // Points already on the surface (within the projection tolerance) stay put, so a
            // later round does not count them as moved again.
            if !delta.is_finite() || delta.length_squared() <= SETTLED_M * SETTLED_M {
                continue;
            }
            let moved_to = q + delta;
            let (local, local_normal) = (
                s.shape_from_world.transform_point3(moved_to),
                s.shape_from_world.transform_vector3(dir),
            );
            let velocity = motion.velocity_at(moved_to, local);
            log.record(f, moved_to, velocity, dir, local, local_normal, owed);
            moved += 1;
        }
        sc.hit_index = found;
    }
    moved
}

/// How far below zero a sign-only value of `geometry` ([`Batch::evaluate`] without gradients)
/// may be while its point is certainly within half the projection tolerance of the surface
/// (such a point is on the surface for the projection, which would leave it where it is), or 0
/// where no such bound is at hand.
///
/// For an undeformed superellipsoid the sign value is `u − 1`, with `u` Barr's inside/outside
/// function, homogeneous of degree `k = 2/e1`: along the ray from the centre through `p` the
/// surface is at `p u^(−1/k)`, so a point inside is at most `|p| (u^(−1/k) − 1)` from it, and
/// `|p| ≤ R = |radii|` inside. That is at most `t = tol/2` when `u ≥ (1 + t/R)^(−k)`, which
/// holds when `1 − u ≤ y/(1 + y)` with `y = k x/(1 + x)`, `x = t/R` (from `ln(1 + x) ≥ x/(1 +
/// x)` and `1 − e^(−y) ≥ y/(1 + y)`). The Newton step the projection would take from such a
/// point is no longer than that ray's distance (Euler's theorem for the normalised
/// `u^(1/k) − 1`), so leaving these points out changes no move. About 38 % of the torso's
/// inside points were such: resting skin the last step left on its muscle. For an undeformed
/// cylinder the value is the signed distance, so the band is `tol/2` itself. Deformed shapes
/// are evaluated in rest space, where these distances do not hold: 0.
fn settled_band(geometry: &ShapeGeometry) -> f32 {
    match geometry.primitive {
        Primitive::Superellipsoid { radii_m, e1, .. } if geometry.is_undeformed() => {
            let x = 0.5 * PROJECTION_TOLERANCE_M / radii_m.length();
            let y = (2.0 / e1) * x / (1.0 + x);
            let band = y / (1.0 + y);
            if band.is_finite() { band.max(0.0) } else { 0.0 }
        }
        // The cylinder's value is the signed distance itself.
        Primitive::Cylinder { .. } if geometry.is_undeformed() => 0.5 * PROJECTION_TOLERANCE_M,
        _ => 0.0,
    }
}

/// Any other shape: extent-box filter over the runs, batched values, batched Newton
/// projection. Returns the points moved.
fn general_stage(
    sc: &mut PassScratch,
    runs: &[(u32, u32)],
    s: &ShapeInstance,
    owed: Owed,
    motion: SurfaceMotion<'_>,
    (extent, ellipsoid): (Vec3, Vec3),
) -> usize {
    let t = &s.shape_from_world;
    sc.batch.clear();
    for &(a, b) in runs {
        let (a, b) = (a as usize, b as usize);
        let filter = Filter::Box {
            shape_from_world: t,
            extent,
            ellipsoid,
        };
        filter_run(sc, a, b, filter, owed);
        sc.batch.extend_mapped(a, &sc.hit_index, &sc.points.q, t);
    }
    if sc.batch.is_empty() {
        return 0;
    }
    let geometry = &s.geometry;
    // Signs first (cheap), then values and gradients of the inside points only, less those
    // the signs already show to be within the projection tolerance of the surface.
    sc.batch.evaluate(geometry, false);
    sc.project
        .assign_inside_of(&sc.batch, settled_band(geometry));
    sc.origin.clone_from(&sc.project.p);
    if sc.project.is_empty() {
        return 0;
    }
    // Newton steps along the gradient, batched, until every point lands on the surface
    // (usually one step: a step's penetration is shallow) or the steps run out.
    sc.project.evaluate(geometry, true);
    for _ in 0..NEWTON_STEPS {
        if sc.project.newton_step() {
            break;
        }
        sc.project.evaluate(geometry, true);
    }
    // Where the batched steps did not land, the exact projection from the original position.
    let n = sc.project.len();
    let mv = &mut sc.moves;
    mv.resize(n);
    mv.mark_converged(&sc.project.value, &sc.project.grad);
    for i in 0..n {
        if mv.converged[i] == 0 {
            let local = Vec3::new(sc.origin[0][i], sc.origin[1][i], sc.origin[2][i]);
            let p = geometry.project(local);
            for c in 0..3 {
                sc.project.p[c][i] = p[c];
            }
        }
    }
    mv.world_moves(&s.world_from_shape, &sc.project.p, &sc.origin, SETTLED_M);
    let shapes = motion
        .start
        .map(|start| (&s.shape_from_world, &start.world_from_shape));
    mv.finish(&sc.project.point, &sc.points.q, shapes, motion.inv_h);
    let mut log = MoveLog::new(&mut sc.points);
    let (mv, project) = (&sc.moves, &sc.project);
    // Every per-entry array sliced to the batch's length: the loop needs no bounds checks.
    let (keep, len, point) = (&mv.keep[..n], &mv.len[..n], &project.point[..n]);
    let (normals, qs, surfaces) = (
        prefix(&mv.normal, n),
        prefix(&mv.q, n),
        prefix(&mv.surface_vel, n),
    );
    let mut moved = 0;
    for i in 0..n {
        if keep[i] == 0 {
            continue;
        }
        let at = |a: &[&[f32]; 3]| Vec3::new(a[0][i], a[1][i], a[2][i]);
        let normal = if len[i] > 1e-9 {
            at(&normals)
        } else {
            outward(geometry, s, project.position(i))
        };
        let local_normal = s.shape_from_world.transform_vector3(normal);
        let (f, local) = (point[i] as usize, project.position(i));
        log.record(f, at(&qs), at(&surfaces), normal, local, local_normal, owed);
        moved += 1;
    }
    moved
}

/// The first `n` entries of each of three SoA arrays.
#[inline(always)]
fn prefix(a: &[Vec<f32>; 3], n: usize) -> [&[f32]; 3] {
    [&a[0][..n], &a[1][..n], &a[2][..n]]
}

/// A run whose gated points are fewer than its length over this is tested point by point (in
/// the first round; later rounds always are, see [`filter_run`]).
const SPARSE_RATIO: usize = 6;

/// The first stage's test of one shape.
enum Filter<'a> {
    /// Strictly inside an undeformed sphere (`|q − center|² < r2`).
    Sphere { center: Vec3, r2: f32 },
    /// Inside a shape's extent box and its bounding ellipsoid (`Σ p_i² w_i ≤ 1` with the weights
    /// `w = 1/E²`), in its own frame.
    Box {
        shape_from_world: &'a Affine3A,
        extent: Vec3,
        ellipsoid: Vec3,
    },
}

/// One shape's turn in one round of a pass: the shape that tests (and moves) points, and which
/// points it owes a test.
///
/// The shapes are visited in order and each sees the points the earlier ones moved
/// (Gauss-Seidel). A point that shape `a` moved in round `r` was then tested at its final
/// position by every shape after `a` in that round, and none of them moved it. So round `r + 1`
/// owes it a test only by the shapes before `a`; a shape after `a` would test the same position
/// with the same arithmetic and find the same answer. A point moved again in round `r + 1` is
/// tested by every later shape of that round, as usual. In the first round every gated point
/// is owed a test.
#[derive(Clone, Copy)]
struct Owed {
    /// The shape running the test (index into the pass's shapes).
    shape: u32,
    /// The current round (0: every gated point is tested).
    round: u8,
}

impl Owed {
    /// Whether point `f` is tested by this shape in this round, by the pass's
    /// [`PointMoves::moved_round`] and [`PointMoves::last_shape`] (passed as slices, so a
    /// loop that pushes hits keeps them in registers).
    #[inline]
    fn test(self, moved_round: &[u8], last_shape: &[u32], f: usize) -> bool {
        self.round == 0 || moved_round[f] == self.round || self.shape < last_shape[f]
    }
}

impl Filter<'_> {
    /// The test for one point, with the same arithmetic as the vectorised kernels.
    #[inline]
    fn contains(&self, q: Vec3) -> bool {
        match *self {
            Filter::Sphere { center: c, r2 } => {
                let (dx, dy, dz) = (q.x - c.x, q.y - c.y, q.z - c.z);
                dx * dx + dy * dy + dz * dz < r2
            }
            Filter::Box {
                shape_from_world,
                extent,
                ellipsoid,
            } => in_box_and_ellipsoid(shape_from_world, extent, ellipsoid, [q.x, q.y, q.z]),
        }
    }
}

/// Runs `filter` over the gated fat points of the run `[a, b)` that `owed` includes and leaves
/// the positions (in the run) of those that pass in `sc.hit_index`.
fn filter_run(sc: &mut PassScratch, a: usize, b: usize, filter: Filter<'_>, owed: Owed) {
    let len = b - a;
    let in_run = if sc.all_gated {
        None
    } else {
        Some(gated_in(&sc.gated, &sc.gated_before, a, b))
    };
    // Later rounds always test point by point: most of their gated points are not owed a test
    // by this shape, which the point-by-point test sees first (the whole-run filter tested
    // about 2 M points per 10 s of the torso for later rounds that moved 301).
    if let Some(points) = in_run.filter(|p| owed.round > 0 || p.len() * SPARSE_RATIO < len) {
        // Few gated points (later rounds, re-checks): test just those. The arrays are read as
        // local slices, which the pushes cannot move.
        let [qx, qy, qz] = &sc.points.q;
        let (qx, qy, qz) = (&qx[..], &qy[..], &qz[..]);
        let (moved_round, last_shape) = (&sc.points.moved_round[..], &sc.points.last_shape[..]);
        let hits = &mut sc.hit_index;
        hits.clear();
        // The owed test first: in later rounds it fails for most points, and it is cheaper
        // than the filter's (both are pure, so the hits are the same).
        for &f in points {
            let f = f as usize;
            if owed.test(moved_round, last_shape, f)
                && filter.contains(Vec3::new(qx[f], qy[f], qz[f]))
            {
                hits.push((f - a) as u32);
            }
        }
        return;
    }
    sc.hit.resize(len.next_multiple_of(8), 0);
    let (qx, qy, qz, gate) = (
        &sc.points.q[0][a..b],
        &sc.points.q[1][a..b],
        &sc.points.q[2][a..b],
        &sc.gate[a..b],
    );
    let hit = &mut sc.hit[..len];
    match filter {
        Filter::Sphere { center, r2 } => sphere_filter(center, r2, qx, qy, qz, gate, hit),
        Filter::Box {
            shape_from_world,
            extent,
            ellipsoid,
        } => box_filter(shape_from_world, extent, ellipsoid, [qx, qy, qz], gate, hit),
    }
    sc.hit[len..].fill(0);
    collect_hits(&sc.hit, &mut sc.hit_index);
    // Only a first round gets here, and it owes every gated point a test.
    debug_assert_eq!(owed.round, 0);
}

/// The gated points in `[a, b)`, a slice of the ascending list `gated`, by the counts of
/// [`index_gates`].
#[inline]
fn gated_in<'a>(gated: &'a [u32], before: &[u32], a: usize, b: usize) -> &'a [u32] {
    &gated[before[a] as usize..before[b] as usize]
}

/// A sparse round's index of its gate bytes (0 or 1 per free point): `gated`, the gated points
/// in ascending order, and `before[f]`, how many of them are below `f` (for `f` in
/// `0..=gate.len()`).
fn index_gates(gate: &[u8], gated: &mut Vec<u32>, before: &mut Vec<u32>) {
    collect_hits(gate, gated);
    // Written by index into a sized array (a push per point kept a capacity check and a
    // length store in the loop: about 1.5 % of the torso's time).
    before.resize(gate.len() + 1, 0);
    let (first, rest) = before.split_at_mut(1);
    first[0] = 0;
    let mut count = 0u32;
    for (b, &g) in rest.iter_mut().zip(gate) {
        count += u32::from(g != 0);
        *b = count;
    }
}

crate::sim::simd::multiversion! {
    /// `hit[i] = 1` where gated fat point `i` is strictly inside the sphere `|q − c|² < r²`.
    fn sphere_filter(
        c: Vec3,
        r2: f32,
        qx: &[f32],
        qy: &[f32],
        qz: &[f32],
        gate: &[u8],
        hit: &mut [u8],
    ) {
        let n = hit.len().min(qx.len()).min(qy.len()).min(qz.len()).min(gate.len());
        for i in 0..n {
            let (dx, dy, dz) = (qx[i] - c.x, qy[i] - c.y, qz[i] - c.z);
            let inside = dx * dx + dy * dy + dz * dz < r2;
            hit[i] = u8::from(inside) & gate[i];
        }
    }
}

crate::sim::simd::multiversion! {
    /// `hit[i] = 1` where gated fat point `i`, mapped by `shape_from_world` to `p`, lies in
    /// the box `|p| ≤ extent` and the ellipsoid `Σ p_j² w_j ≤ 1` (the weights `w = 1/E²`, zero
    /// for no ellipsoid).
    fn box_filter(
        shape_from_world: &Affine3A,
        extent: Vec3,
        w: Vec3,
        q: [&[f32]; 3],
        gate: &[u8],
        hit: &mut [u8],
    ) {
        let [qx, qy, qz] = q;
        let n = hit.len().min(qx.len()).min(qy.len()).min(qz.len()).min(gate.len());
        for i in 0..n {
            let inside = in_box_and_ellipsoid(shape_from_world, extent, w, [qx[i], qy[i], qz[i]]);
            hit[i] = u8::from(inside) & gate[i];
        }
    }
}

/// Whether the world point `q`, mapped by `shape_from_world` to `p`, lies in the box
/// `|p| ≤ extent` and the ellipsoid `Σ p_j² w_j ≤ 1` ([`within_bounds`]): the test of
/// [`box_filter`] (inlined into each of its copies, branch-free) and of [`Filter::contains`],
/// with the same arithmetic.
#[inline(always)]
fn in_box_and_ellipsoid(shape_from_world: &Affine3A, extent: Vec3, w: Vec3, q: [f32; 3]) -> bool {
    let m = shape_from_world.matrix3;
    let (cx, cy, cz, o) = (m.x_axis, m.y_axis, m.z_axis, shape_from_world.translation);
    let lx = cx.x * q[0] + cy.x * q[1] + cz.x * q[2] + o.x;
    let ly = cx.y * q[0] + cy.y * q[1] + cz.y * q[2] + o.y;
    let lz = cx.z * q[0] + cy.z * q[1] + cz.z * q[2] + o.z;
    within_bounds(Vec3::new(lx, ly, lz), extent, w)
}

/// Outward unit normal of a shape at a surface point, world.
fn outward(geometry: &ShapeGeometry, s: &ShapeInstance, p_shape: Vec3) -> Vec3 {
    s.world_from_shape
        .transform_vector3(geometry.gradient(p_shape))
        .normalize_or_zero()
}

/// Deepest penetration of any free point's fat point into any shape, metres (brute force over
/// every point and shape: for tests and checks, not the hot path).
pub fn max_depth_m(
    around: usize,
    along: usize,
    grid: &[Vec<f32>; 3],
    normals: &[Vec<f32>; 3],
    fat_m: &[f32],
    shapes: &[ShapeInstance],
) -> f32 {
    let m = around;
    let free = m * (along - 2);
    let mut worst = 0.0f32;
    for f in 0..free {
        let k = m + f;
        let p = Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
        let n = Vec3::new(normals[0][k], normals[1][k], normals[2][k]);
        let q = p - n * fat_m[f];
        for s in shapes {
            let local = s.to_shape(q);
            if s.geometry.value(local) < 0.0 {
                let depth = (s.geometry.project(local) - local).length();
                worst = worst.max(depth);
            }
        }
    }
    worst
}

/// The free points within one grid step (around or along, periodic around) of `points`, each
/// once and in ascending order, into `out` (`flags` is scratch of one byte per free point).
/// The points are marked, then listed by a scan of the marks, so the list needs no sort (a
/// sort of the re-checks' lists of about 200 points was most of a re-check's set-up).
pub fn neighbourhood(
    around: usize,
    free: usize,
    points: &[u32],
    flags: &mut Vec<u8>,
    out: &mut Vec<u32>,
) {
    flags.clear();
    flags.resize(free, 0);
    let m = around;
    for &p in points {
        let f = p as usize;
        if f >= free {
            continue;
        }
        let (i, row) = (f % m, f / m);
        flags[f] = 1;
        flags[row * m + (i + m - 1) % m] = 1;
        flags[row * m + (i + 1) % m] = 1;
        if f >= m {
            flags[f - m] = 1;
        }
        if f + m < free {
            flags[f + m] = 1;
        }
    }
    collect_hits(flags, out);
}

#[cfg(test)]
mod tests {
    use glam::Quat;

    use super::*;
    use crate::character::Resolved;
    use crate::pose::Pose;
    use crate::test_noise::Noise;

    /// Free points of an `m × n` grid as the SoA grid (rows 0 and n−1 unused but present),
    /// with unit normals and fat.
    struct Scene {
        m: usize,
        n: usize,
        grid: [Vec<f32>; 3],
        normals: [Vec<f32>; 3],
        fat: Vec<f32>,
        x: Vec<f32>,
        v: Vec<f32>,
    }

    impl Scene {
        fn new(m: usize, n: usize, points: &[Vec3], normals: &[Vec3], fat: &[f32]) -> Self {
            let total = m * n;
            let free = m * (n - 2);
            assert_eq!(points.len(), free);
            let mut grid: [Vec<f32>; 3] = [vec![9.0; total], vec![9.0; total], vec![9.0; total]];
            let mut nr: [Vec<f32>; 3] = [vec![0.0; total], vec![1.0; total], vec![0.0; total]];
            let mut x = vec![0.0; 3 * free];
            for f in 0..free {
                for c in 0..3 {
                    grid[c][m + f] = points[f][c];
                    nr[c][m + f] = normals[f][c];
                    x[c * free + f] = points[f][c];
                }
            }
            Self {
                m,
                n,
                grid,
                normals: nr,
                fat: fat.to_vec(),
                x,
                v: vec![0.0; 3 * free],
            }
        }

        fn enforce(
            &mut self,
            start: &[ShapeInstance],
            end: &[ShapeInstance],
            h_s: f32,
        ) -> ConstraintOutcome {
            let input = ConstraintInput {
                around: self.m,
                along: self.n,
                shapes_end: end,
                shapes_start: start,
                h_s,
                fat_m: &self.fat,
                max_fat_m: self.fat.iter().fold(0.0, |a, b| a.max(*b)),
                k_parallel: 0.0,
                k_perpendicular: 1.0,
                max_speed_m_per_s: 0.0,
                recheck_m: 1.0,
                rounds: MAX_ROUNDS,
            };
            let mut broad = Broadphase {
                margin_m: 0.02,
                ..Default::default()
            };
            let mut touched = Vec::new();
            enforce(
                &input,
                &mut broad,
                &mut self.grid,
                &self.normals,
                &mut self.x,
                &mut self.v,
                None,
                &mut touched,
            )
        }

        fn point(&self, f: usize) -> Vec3 {
            let k = self.m + f;
            Vec3::new(self.grid[0][k], self.grid[1][k], self.grid[2][k])
        }

        fn fat_point(&self, f: usize) -> Vec3 {
            let k = self.m + f;
            self.point(f)
                - Vec3::new(self.normals[0][k], self.normals[1][k], self.normals[2][k])
                    * self.fat[f]
        }
    }

    fn instance(
        primitive: Primitive,
        deformations: &[Resolved],
        at: Vec3,
        turn: Quat,
    ) -> ShapeInstance {
        ShapeInstance::new(
            ShapeGeometry::new(primitive, deformations),
            Pose::new(at, turn),
        )
    }

    #[test]
    fn the_settled_band_only_spares_points_within_half_the_tolerance() {
        // Points inside undeformed superellipsoids and cylinders at depths around the
        // tolerance, along rays in many directions: every point the band spares from the
        // projection (sign value at least −band) is within tol/2 of the surface (for a
        // superellipsoid its distance along the ray from the centre, which bounds the
        // distance; a cylinder's value is the distance), and points well inside that are
        // spared, so the band is not empty.
        let tol = PROJECTION_TOLERANCE_M;
        let shapes = [
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.04, 0.09, 0.05),
                e1: 1.0,
                e2: 1.0,
            },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.03, 0.12, 0.06),
                e1: 0.4,
                e2: 0.7,
            },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.05, 0.05, 0.02),
                e1: 1.8,
                e2: 1.3,
            },
            Primitive::Cylinder {
                radius_m: 0.05,
                half_length_m: 0.15,
            },
        ];
        for primitive in shapes {
            let geometry = ShapeGeometry::new(primitive, &[]);
            let band = settled_band(&geometry);
            assert!(band > 0.0, "{primitive:?}");
            let mut batch = Batch::default();
            let mut depths = Vec::new();
            for i in 0..400 {
                // A spread of directions (a spiral over the sphere) and depths 0..2 tol.
                let t = (i as f32 + 0.5) / 400.0;
                let (polar, azimuth) = ((1.0 - 2.0 * t).acos(), 2.4 * i as f32);
                let dir = Vec3::new(
                    polar.sin() * azimuth.cos(),
                    polar.cos(),
                    polar.sin() * azimuth.sin(),
                );
                let surface = primitive.radial_projection(dir);
                let depth = 2.0 * tol * ((i * 37) % 100) as f32 / 100.0;
                let p = surface - surface.normalize() * depth;
                batch.push(i, p);
                depths.push(match primitive {
                    Primitive::Cylinder { .. } => -primitive.value(p),
                    _ => depth,
                });
            }
            batch.evaluate(&geometry, false);
            let mut spared_deep = 0;
            for (i, &depth) in depths.iter().enumerate() {
                let spared = batch.value[i] >= -band;
                assert!(
                    !spared || depth <= 0.5 * tol * 1.0001,
                    "{primitive:?}: a point {depth} m deep is spared"
                );
                spared_deep += usize::from(spared && depth >= 0.1 * tol);
            }
            assert!(spared_deep > 0, "{primitive:?}: the band spares nothing");
        }
        // Deformed shapes get no band.
        let bent = ShapeGeometry::new(
            shapes[0],
            &[Resolved::Bend {
                curvature_per_m: 2.0,
            }],
        );
        assert_eq!(settled_band(&bent), 0.0);
    }

    #[test]
    fn every_fat_point_ends_outside_every_separate_shape_and_outside_points_stay() {
        // Separate (non-overlapping) shapes of every kind, deformed and turned, and points
        // scattered through and around them: one pass must push every fat point out
        // (brute force over all shapes checks it), and leave the points that were outside.
        let shapes = vec![
            instance(
                Primitive::Sphere { radius_m: 0.06 },
                &[],
                Vec3::new(-0.3, 0.0, 0.0),
                Quat::IDENTITY,
            ),
            instance(
                Primitive::Superellipsoid {
                    radii_m: Vec3::new(0.07, 0.12, 0.05),
                    e1: 0.8,
                    e2: 1.0,
                },
                &[Resolved::Twist {
                    rate_rad_per_m: 2.0,
                }],
                Vec3::new(-0.1, 0.0, 0.0),
                Quat::from_rotation_z(0.4),
            ),
            instance(
                Primitive::Superellipsoid {
                    radii_m: Vec3::new(0.06, 0.1, 0.06),
                    e1: 0.6,
                    e2: 0.9,
                },
                &[
                    Resolved::Bend {
                        curvature_per_m: 2.0,
                    },
                    Resolved::Taper { rate_per_m: 1.0 },
                ],
                Vec3::new(0.1, 0.0, 0.0),
                Quat::from_rotation_x(-0.7),
            ),
            instance(
                Primitive::Cylinder {
                    radius_m: 0.03,
                    half_length_m: 0.1,
                },
                &[],
                Vec3::new(0.3, 0.0, 0.0),
                Quat::from_rotation_y(0.3),
            ),
        ];
        let (m, n) = (40usize, 27usize);
        let free = m * (n - 2);
        let mut noise = Noise(77);
        let points: Vec<Vec3> = (0..free)
            .map(|_| {
                Vec3::new(
                    noise.next() * 0.42,
                    noise.next() * 0.16,
                    noise.next() * 0.12,
                )
            })
            .collect();
        let normals: Vec<Vec3> = (0..free)
            .map(|_| noise.vec().normalize_or(Vec3::Y))
            .collect();
        let fat: Vec<f32> = (0..free).map(|_| 0.005 + 0.005 * noise.next()).collect();
        let mut scene = Scene::new(m, n, &points, &normals, &fat);
        let inside_before = (0..free)
            .filter(|&f| {
                shapes
                    .iter()
                    .any(|s| s.value_world(scene.fat_point(f)) < 0.0)
            })
            .count();
        assert!(
            inside_before > 50,
            "the scene must put many points inside: {inside_before}"
        );
        let outcome = scene.enforce(&shapes, &shapes, 0.01);
        assert_eq!(outcome.corrected as usize, inside_before);
        for f in 0..free {
            let q = scene.fat_point(f);
            for s in &shapes {
                let (v, g) = s.value_and_gradient_world(q);
                let depth = -v / g.length().max(1e-6);
                assert!(
                    depth <= 2e-5,
                    "point {f} still {depth} m inside {:?}",
                    s.geometry.primitive
                );
            }
            let was_inside = shapes
                .iter()
                .any(|s| s.value_world(points[f] - normals[f] * fat[f]) < 0.0);
            if !was_inside {
                assert_eq!(scene.point(f), points[f], "point {f} was outside and moved");
            }
        }
    }

    #[test]
    fn neighbourhood_lists_each_neighbour_once_in_order() {
        // A 6-around grid with 4 free rows: periodic around, cut at the first and last row.
        let (m, free) = (6usize, 24usize);
        let mut flags = Vec::new();
        let mut out = Vec::new();
        for points in [
            vec![],
            vec![0u32],
            vec![5, 0],
            vec![23, 12, 12, 7],
            vec![99, 3],
        ] {
            neighbourhood(m, free, &points, &mut flags, &mut out);
            let mut want = std::collections::BTreeSet::new();
            for &p in points.iter().filter(|&&p| (p as usize) < free) {
                let (f, i, row) = (p as usize, p as usize % m, p as usize / m);
                want.extend([f, row * m + (i + m - 1) % m, row * m + (i + 1) % m]);
                want.extend(
                    [f.checked_sub(m), Some(f + m).filter(|&g| g < free)]
                        .into_iter()
                        .flatten(),
                );
            }
            let want: Vec<u32> = want.into_iter().map(|f| f as u32).collect();
            assert_eq!(out, want, "points {points:?}");
        }
    }

    #[test]
    fn a_point_pushed_by_a_moving_muscle_takes_its_velocity() {
        // A sphere moving up at 1 m/s reaches a resting point from below: the point ends on
        // its top with the sphere's velocity (k∥ = 0: no bounce), not the opposite.
        let h = 0.01;
        let start = vec![instance(
            Primitive::Sphere { radius_m: 0.05 },
            &[],
            Vec3::ZERO,
            Quat::IDENTITY,
        )];
        let end = vec![instance(
            Primitive::Sphere { radius_m: 0.05 },
            &[],
            Vec3::new(0.0, 0.01, 0.0),
            Quat::IDENTITY,
        )];
        let points = [
            Vec3::new(0.0, 0.055, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(-1.0, 0.0, 0.0),
        ];
        let normals = [Vec3::Y; 3];
        let mut scene = Scene::new(3, 3, &points, &normals, &[0.0; 3]);
        let outcome = scene.enforce(&start, &end, h);
        assert_eq!(outcome.corrected, 1);
        assert!(
            (scene.point(0) - Vec3::new(0.0, 0.06, 0.0)).length() < 1e-5,
            "{}",
            scene.point(0)
        );
        let v = Vec3::new(scene.v[0], scene.v[3], scene.v[6]);
        assert!(
            (v - Vec3::Y).length() < 1e-4,
            "velocity {v}, expected the sphere's (0, 1, 0)"
        );
    }

    #[test]
    fn overlapping_shapes_resolve_like_plain_gauss_seidel_rounds() {
        // Three overlapping spheres and points in and around their overlaps: a shape's push
        // can land a point in an earlier shape, which the next round must fix. The pass must
        // give what plain Gauss-Seidel gives (every shape tests every point, in shape order,
        // for MAX_ROUNDS rounds), although its later rounds test only the points moved in the
        // round before, each against the shapes before the one that moved it.
        let spheres = [
            (Vec3::new(0.0, 0.0, 0.0), 0.1),
            (Vec3::new(0.12, 0.0, 0.0), 0.05),
            (Vec3::new(0.06, 0.07, 0.0), 0.06),
        ];
        let shapes: Vec<ShapeInstance> = spheres
            .iter()
            .map(|&(c, r)| instance(Primitive::Sphere { radius_m: r }, &[], c, Quat::IDENTITY))
            .collect();
        let (m, n) = (24usize, 22usize);
        let free = m * (n - 2);
        let mut noise = Noise(5);
        let points: Vec<Vec3> = (0..free)
            .map(|_| Vec3::new(0.09, 0.04, 0.0) + noise.vec() * Vec3::new(0.05, 0.05, 0.03))
            .collect();
        let normals: Vec<Vec3> = (0..free)
            .map(|_| noise.vec().normalize_or(Vec3::Y))
            .collect();
        let fat = vec![0.004; free];
        let mut scene = Scene::new(m, n, &points, &normals, &fat);
        // The reference, on the fat points.
        let mut expected: Vec<Vec3> = (0..free).map(|f| scene.fat_point(f)).collect();
        let mut resolved_by_later_rounds = 0;
        for round in 0..MAX_ROUNDS {
            let mut changed = false;
            for &(c, r) in &spheres {
                for q in &mut expected {
                    let d = *q - c;
                    if d.length_squared() < r * r {
                        let delta = (c + d / d.length() * r) - *q;
                        if delta.length_squared() > SETTLED_M * SETTLED_M {
                            *q += delta;
                            changed = true;
                            resolved_by_later_rounds += usize::from(round > 0);
                        }
                    }
                }
            }
            if !changed {
                break;
            }
        }
        assert!(
            resolved_by_later_rounds > 20,
            "the scene must need the later rounds: {resolved_by_later_rounds} moves"
        );
        scene.enforce(&shapes, &shapes, 0.01);
        for (f, want) in expected.iter().enumerate() {
            let got = scene.fat_point(f);
            assert!(
                (got - *want).length() < 1e-6,
                "point {f}: {got} instead of {want}"
            );
        }
    }

    /// The branch-free summary and report agree with a point-by-point scan
    /// (`ConstraintOutcome::report`'s rule) on every SIMD copy: counts, both maxima, the worst
    /// point, the re-check list, infinite corrections, none moved.
    #[test]
    fn moves_summary_matches_a_scan_of_the_moved_points() {
        use crate::sim::simd::{SimdLevel, with_simd_level};
        let mut noise = Noise(0x5eed_1234);
        for n in [0usize, 1, 7, 8, 9, 61, 960] {
            for moved_share in [0.0f32, 0.3, 1.0] {
                let mut applied = vec![-1.0f32; n];
                let mut component = vec![-1.0f32; n];
                for f in 0..n {
                    if (noise.next() + 1.0) / 2.0 < moved_share {
                        applied[f] = (noise.next() + 1.0) * 3e-3 + 1e-7;
                        component[f] = applied[f] * (0.6 + 0.2 * noise.next());
                    }
                }
                if n == 61 && moved_share > 0.0 {
                    applied[40] = f32::INFINITY;
                    component[40] = f32::INFINITY;
                }
                let last_shape: Vec<u32> = (0..n as u32).map(|f| f % 5).collect();
                let mut want = ConstraintOutcome::default();
                let mut touched = Vec::new();
                for f in 0..n {
                    if applied[f] >= 0.0 {
                        want.report(
                            f,
                            applied[f],
                            component[f],
                            last_shape[f],
                            2e-3,
                            &mut touched,
                        );
                    }
                }
                let mut got = ConstraintOutcome::default();
                let mut got_touched = vec![7];
                got.report_all(&applied, &component, &last_shape, 2e-3, &mut got_touched);
                assert_eq!(got, want, "n {n}, {moved_share}");
                assert_eq!(got_touched[0], 7, "appends to the list");
                assert_eq!(got_touched[1..], touched[..], "n {n}, {moved_share}");
                for level in SimdLevel::ALL {
                    let got = with_simd_level(level, || moves_summary(&applied, &component));
                    assert_eq!(got.moved, want.corrected, "n {n}, {moved_share}, {level:?}");
                    assert_eq!(
                        got.max_correction_m, want.max_correction_m,
                        "n {n}, {level:?}"
                    );
                    assert_eq!(
                        got.max_component_m, want.max_component_m,
                        "n {n}, {level:?}"
                    );
                }
            }
        }
    }
}
