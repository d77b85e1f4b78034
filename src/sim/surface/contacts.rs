//! Resting contact from one step to the next: which free skin points a muscle holds, the
//! reaction that holds them, and the error the constraint phase absorbs at contacts.
//!
//! The paper's non-penetration (section 4.2.3, [`super::constraints`]) is positional: a point
//! that ends a step inside a muscle is moved back to its surface. Skin resting on a muscle
//! (gravity and the tissue springs press about 700 of the torso's 960 free points onto their
//! muscles) then sinks by about `h² |a| / 2` in every step and is pushed out again: every step
//! pays a projection, eq. 13 and a re-check of the neighbourhood for each of them.
//!
//! A muscle that a point rests on also bears what presses the point into it. Here a point the
//! constraint phase pushed is *held* for the next steps: its position-dependent acceleration
//! (gravity, elasticity, tissue springs) loses the component into the muscle,
//! `a ← a − min(a·n, 0) n`, as a contact reaction would remove it (a one-sided reaction
//! constraint in the manner of Platt and Barr, which the paper cites as the alternative to its
//! projection). The reaction never pulls, so forces that draw a point away from the muscle lift
//! it off by themselves. The projection stays the guarantee: every point is still tested after
//! every step and pushed out when it is inside; the reaction only spares resting points the
//! sink-and-push of every step.
//!
//! A hold lasts while the contact is real. After every constraint phase each held point's fat
//! point is compared with where its push left it on the muscle, a point fixed in the muscle's
//! own frame (so it follows the skeleton), and the hold ends when
//! - the fat point is more than [`HOLD_GAP_M`] off the muscle's tangent plane there (the muscle
//!   moved away, or the point lifted off),
//! - it slid more than [`HOLD_SLIDE_M`] along that plane (a plane is only close to a curved
//!   surface near where it touches: `t² / 2R` off it at a distance `t`, 25 µm at 1 mm on a
//!   2 cm radius), or
//! - [`HOLD_STEPS`] steps passed since the push (this also bounds what the frame check does not
//!   see: a muscle's joint-tied taper, twist and bend).
//!
//! A released point falls back onto the muscle under the full forces and is pushed again,
//! which renews its contact.
//!
//! Everything is kept per free point in structure-of-arrays form, so the integrator's two uses
//! ([`hold`], [`drop_inward_error`]) are single vectorised passes and the bookkeeping after a
//! constraint phase ([`ContactState::update`]) is one loop over the free points.

use crate::character::ShapeInstance;

/// Steps a contact holds its point after the push that made it (the push's own step counts
/// as the first).
pub const HOLD_STEPS: u8 = 8;
/// Largest distance of a held point's fat point off the muscle's tangent plane at its contact,
/// metres (the projection tolerance).
pub const HOLD_GAP_M: f32 = crate::character::PROJECTION_TOLERANCE_M;
/// Largest distance a held point may slide along that tangent plane from its contact, metres.
pub const HOLD_SLIDE_M: f32 = 1.0e-3;

/// `shape` of a point without a contact.
const NONE: u32 = u32::MAX;

/// Per free point: the contact the constraint phase left it in. Part of the model's state, so a
/// snapshot or checkpoint continues exactly as the run it was taken from.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct ContactState {
    /// Index of the shape the point rests on, or [`NONE`].
    shape: Vec<u32>,
    /// Steps since the push that made the contact (0: pushed in the step that made the state).
    age: Vec<u8>,
    /// Where the push left the fat point, in that shape's frame, metres.
    surface_shape: [Vec<f32>; 3],
    /// The push direction (the muscle's outward unit normal there), in that shape's frame.
    normal_shape: [Vec<f32>; 3],
    /// World unit normal of a held point's muscle, zero where the point is not held: the next
    /// step's reaction ([`hold`]).
    hold: [Vec<f32>; 3],
    /// World unit normal of every point pushed in the last step, held, or released in it, zero
    /// elsewhere: the next step's error estimate leaves the inward error along it to the
    /// constraints ([`drop_inward_error`]).
    absorb: [Vec<f32>; 3],
    /// With holding off: for a point the last step's full pass pushed, that push's direction
    /// (a later pass of the phase may have pushed it again, into `absorb`), zero elsewhere; its
    /// inward error is left to the constraints too (a point pushed out of one muscle and then
    /// out of an overlapping one, or again after its neighbours' normals turned, moved against
    /// both). Without it the arm's projection alone took 11 % more steps (1697 instead of 1560
    /// in 10 s of its motion); with holding on it made no difference to the step counts and
    /// cost 4 % of the torso's time, so it is zero there.
    absorb_first: [Vec<f32>; 3],
    /// How many points `hold` holds.
    held: usize,
    /// How many points `absorb_first` covers.
    firsts: usize,
}

/// What the constraint phase left at one free point, for [`ContactState::update`].
pub(super) struct PhaseEnd<'a> {
    /// Per free point, non-zero where any pass of the phase pushed the point.
    pub pushed: &'a [u8],
    /// Per free point, the shape that pushed it last (valid where `pushed`).
    pub last_shape: &'a [u32],
    /// Per free point, the world direction of its last push (valid where `pushed`).
    pub last_normal: &'a [Vec<f32>; 3],
    /// The fat points after the phase, world, metres (SoA over the free points).
    pub fat_points: &'a [Vec<f32>; 3],
    /// The shapes of the phase (at the end of its step).
    pub shapes: &'a [ShapeInstance],
    /// Per free point, non-zero where the phase's full pass pushed the point (read with holding
    /// off only).
    pub first_pushed: &'a [u8],
    /// The world direction of that push (the later passes overwrite `last_normal`).
    pub first_normal: &'a [Vec<f32>; 3],
}

impl ContactState {
    /// No contacts, for `free` points.
    pub fn clear(&mut self, free: usize) {
        self.held = 0;
        self.firsts = 0;
        self.shape.clear();
        self.shape.resize(free, NONE);
        self.age.clear();
        self.age.resize(free, 0);
        for a in self
            .surface_shape
            .iter_mut()
            .chain(&mut self.normal_shape)
            .chain(&mut self.hold)
            .chain(&mut self.absorb)
            .chain(&mut self.absorb_first)
        {
            a.clear();
            a.resize(free, 0.0);
        }
    }

    /// Whether the arrays are sized for `free` points.
    fn sized(&self, free: usize) -> bool {
        self.shape.len() == free
            && self.age.len() == free
            && [
                &self.surface_shape,
                &self.normal_shape,
                &self.hold,
                &self.absorb,
                &self.absorb_first,
            ]
            .iter()
            .all(|a| a.iter().all(|c| c.len() == free))
    }

    /// Points with a contact (pushed in the last step, or held since an earlier push).
    #[cfg(test)]
    pub fn contact_points(&self) -> usize {
        self.shape.iter().filter(|&&k| k != NONE).count()
    }

    /// Points the last step's constraint phase pushed.
    #[cfg(test)]
    pub fn pushed_points(&self) -> usize {
        (self.shape.iter().zip(&self.age))
            .filter(|&(&k, &age)| k != NONE && age == 0)
            .count()
    }

    /// Points the next step holds (their reaction normal is set).
    pub fn held_points(&self) -> usize {
        self.held
    }

    /// Ends every hold (holding was switched off); the contacts stay for the error estimate.
    pub fn release_all(&mut self) {
        for c in &mut self.hold {
            c.iter_mut().for_each(|v| *v = 0.0);
        }
        self.held = 0;
    }

    /// Replaces `self` with the contacts after a constraint phase that started from `old` (the
    /// contacts of the state the step started from): the points the phase pushed get a new
    /// contact, held; the others keep a held contact of `old`, one step older, while it passes
    /// the checks of the module docs; the rest have none. With `holding` false nobody is held
    /// and the contacts are this phase's pushes alone (the paper's projection; they still serve
    /// the error estimate). `table` is scratch.
    pub fn update(
        &mut self,
        old: &ContactState,
        end: &PhaseEnd<'_>,
        holding: bool,
        table: &mut ShapeTable,
    ) {
        let free = end.pushed.len();
        self.clear(free);
        let sized = |a: &[Vec<f32>; 3]| a.iter().all(|c| c.len() >= free);
        let inputs_ok = end.last_shape.len() >= free
            && sized(end.last_normal)
            && sized(end.fat_points)
            && sized(end.first_normal)
            && end.first_pushed.len() >= free;
        if !inputs_ok {
            return;
        }
        let empty;
        let old = if old.sized(free) {
            old
        } else {
            let mut e = ContactState::default();
            e.clear(free);
            empty = e;
            &empty
        };
        let Self {
            shape,
            age,
            surface_shape: [s0, s1, s2],
            normal_shape: [m0, m1, m2],
            hold: [h0, h1, h2],
            absorb: [a0, a1, a2],
            absorb_first: [f0, f1, f2],
            held,
            firsts,
        } = self;
        let [fn0, fn1, fn2] = end.first_normal;
        let [l0, l1, l2] = end.last_normal;
        let [q0, q1, q2] = end.fat_points;
        let [oh0, oh1, oh2] = &old.hold;
        let [os0, os1, os2] = &old.surface_shape;
        let [on0, on1, on2] = &old.normal_shape;
        // The shapes in chunks the table holds (one chunk for any character of up to
        // `TABLE_SHAPES` shapes).
        for first in (0..end.shapes.len()).step_by(TABLE_SHAPES) {
            let chunk = &end.shapes[first..end.shapes.len().min(first + TABLE_SHAPES)];
            table.fill(chunk);
            let (holds, first_pushes) = update_pass(
                end.pushed,
                end.last_shape,
                l0,
                l1,
                l2,
                q0,
                q1,
                q2,
                &old.shape,
                &old.age,
                oh0,
                oh1,
                oh2,
                os0,
                os1,
                os2,
                on0,
                on1,
                on2,
                holding,
                &table.columns,
                first as u32,
                chunk.len() as u32,
                shape,
                age,
                s0,
                s1,
                s2,
                m0,
                m1,
                m2,
                h0,
                h1,
                h2,
                a0,
                a1,
                a2,
                end.first_pushed,
                fn0,
                fn1,
                fn2,
                f0,
                f1,
                f2,
            );
            *held += holds;
            *firsts += first_pushes;
        }
    }

    /// The contact reaction: removes `min(a·n, 0) n` from the acceleration `a` (SoA
    /// `[x…, y…, z…]` over the free points) of every held point, so its muscle bears what
    /// presses it in.
    pub fn hold(&self, a: &mut [f32]) {
        let free = a.len() / 3;
        if self.shape.len() != free || self.hold.iter().any(|c| c.len() != free) {
            return;
        }
        let [a0, a1, a2] = super::forces::blocks_mut(a, free);
        let [n0, n1, n2] = &self.hold;
        remove_inward(n0, n1, n2, a0, a1, a2, -1.0);
    }

    /// Removes `max(e·n, 0) n` from the error `e` (SoA `[x…, y…, z…]` over the free points) of
    /// each point with a contact of the last step, held or just released, along its contact
    /// normal (and, with holding off, along its full-pass push): the step went further into the muscle
    /// than Euler's, and the constraint phase replaces that motion (checked against ε_c,
    /// section 4.2.3).
    pub fn drop_inward_error(&self, error: &mut [f32]) {
        let free = error.len() / 3;
        if !self.sized(free) {
            return;
        }
        let [e0, e1, e2] = super::forces::blocks_mut(error, free);
        let [n0, n1, n2] = &self.absorb;
        remove_inward(n0, n1, n2, e0, e1, e2, 1.0);
        if self.firsts > 0 {
            let [n0, n1, n2] = &self.absorb_first;
            remove_inward(n0, n1, n2, e0, e1, e2, 1.0);
        }
    }
}

/// Shapes a [`ShapeTable`] holds at once ([`ContactState::update`] goes over a character with
/// more shapes in chunks of this many).
pub const TABLE_SHAPES: usize = 256;

/// Up to [`TABLE_SHAPES`] shapes' `shape_from_world` transforms as twelve fixed-size arrays (the
/// columns of the rotation, then the translation), so a vectorised loop over points can look
/// each point's shape up by index (a gather) without bounds checks.
#[derive(Debug, Clone)]
pub(super) struct ShapeTable {
    columns: Box<[[f32; TABLE_SHAPES]; 12]>,
}

impl Default for ShapeTable {
    fn default() -> Self {
        Self {
            columns: Box::new([[0.0; TABLE_SHAPES]; 12]),
        }
    }
}

impl ShapeTable {
    /// Entry `k` becomes `shapes[k]` (at most [`TABLE_SHAPES`] are taken).
    fn fill(&mut self, shapes: &[ShapeInstance]) {
        for (k, s) in shapes.iter().take(TABLE_SHAPES).enumerate() {
            let t = &s.shape_from_world;
            let m = t.matrix3;
            let values = [
                m.x_axis.x,
                m.x_axis.y,
                m.x_axis.z,
                m.y_axis.x,
                m.y_axis.y,
                m.y_axis.z,
                m.z_axis.x,
                m.z_axis.y,
                m.z_axis.z,
                t.translation.x,
                t.translation.y,
                t.translation.z,
            ];
            for (c, v) in self.columns.iter_mut().zip(values) {
                c[k] = v;
            }
        }
    }
}

crate::sim::simd::multiversion! {
    /// [`ContactState::update`] (returning how many points it holds and how many got a
    /// full-pass direction) for the free points whose shape (the shape of their push in
    /// this phase if any, else of their old contact) is one of the table's `count` shapes,
    /// which are the character's shapes `first..first + count`; the outputs of every other
    /// point are left as they are (the caller starts them at "no contact"). Branch-free: every
    /// point's shape is looked up in the table (a gather), its fat point mapped into that
    /// shape's frame, and the outputs chosen by selects, so the loop vectorises. Every slice is
    /// its own argument, so the compiler knows they do not overlap.
    fn update_pass(
        pushed: &[u8],
        last_shape: &[u32],
        l0: &[f32],
        l1: &[f32],
        l2: &[f32],
        q0: &[f32],
        q1: &[f32],
        q2: &[f32],
        old_shape: &[u32],
        old_age: &[u8],
        oh0: &[f32],
        oh1: &[f32],
        oh2: &[f32],
        os0: &[f32],
        os1: &[f32],
        os2: &[f32],
        on0: &[f32],
        on1: &[f32],
        on2: &[f32],
        holding: bool,
        table: &[[f32; TABLE_SHAPES]; 12],
        first: u32,
        count: u32,
        shape: &mut [u32],
        age: &mut [u8],
        s0: &mut [f32],
        s1: &mut [f32],
        s2: &mut [f32],
        m0: &mut [f32],
        m1: &mut [f32],
        m2: &mut [f32],
        h0: &mut [f32],
        h1: &mut [f32],
        h2: &mut [f32],
        a0: &mut [f32],
        a1: &mut [f32],
        a2: &mut [f32],
        first_pushed: &[u8],
        fn0: &[f32],
        fn1: &[f32],
        fn2: &[f32],
        f0: &mut [f32],
        f1: &mut [f32],
        f2: &mut [f32],
    ) -> (usize, usize) {
        let n = pushed.len().min(shape.len());
        let (pushed, last_shape) = (&pushed[..n], &last_shape[..n]);
        let (l0, l1, l2) = (&l0[..n], &l1[..n], &l2[..n]);
        let (q0, q1, q2) = (&q0[..n], &q1[..n], &q2[..n]);
        let (old_shape, old_age) = (&old_shape[..n], &old_age[..n]);
        let (oh0, oh1, oh2) = (&oh0[..n], &oh1[..n], &oh2[..n]);
        let (os0, os1, os2) = (&os0[..n], &os1[..n], &os2[..n]);
        let (on0, on1, on2) = (&on0[..n], &on1[..n], &on2[..n]);
        let (shape, age) = (&mut shape[..n], &mut age[..n]);
        let (s0, s1, s2) = (&mut s0[..n], &mut s1[..n], &mut s2[..n]);
        let (m0, m1, m2) = (&mut m0[..n], &mut m1[..n], &mut m2[..n]);
        let (h0, h1, h2) = (&mut h0[..n], &mut h1[..n], &mut h2[..n]);
        let (a0, a1, a2) = (&mut a0[..n], &mut a1[..n], &mut a2[..n]);
        let first_pushed = &first_pushed[..n];
        let (fn0, fn1, fn2) = (&fn0[..n], &fn1[..n], &fn2[..n]);
        let (f0, f1, f2) = (&mut f0[..n], &mut f1[..n], &mut f2[..n]);
        let (mut held_count, mut first_count) = (0u32, 0u32);
        for f in 0..n {
            let p = pushed[f] != 0;
            let k = if p { last_shape[f] } else { old_shape[f] };
            let local = k.wrapping_sub(first);
            let here = local < count;
            let r: [f32; 12] = std::array::from_fn(|c| table[c][local as usize % TABLE_SHAPES]);
            // The fat point in the shape frame: R q + t (R's columns are r[0..3], r[3..6],
            // r[6..9], t is r[9..12]).
            let (qx, qy, qz) = (q0[f], q1[f], q2[f]);
            let lx = r[0] * qx + r[3] * qy + r[6] * qz + r[9];
            let ly = r[1] * qx + r[4] * qy + r[7] * qz + r[10];
            let lz = r[2] * qx + r[5] * qy + r[8] * qz + r[11];
            // A new push: its world direction, and that direction in the shape frame.
            let (wx, wy, wz) = (l0[f], l1[f], l2[f]);
            let px = r[0] * wx + r[3] * wy + r[6] * wz;
            let py = r[1] * wx + r[4] * wy + r[7] * wz;
            let pz = r[2] * wx + r[5] * wy + r[8] * wz;
            // An old contact: how far the fat point is off its tangent plane and along it.
            let (nx, ny, nz) = (on0[f], on1[f], on2[f]);
            let (dx, dy, dz) = (lx - os0[f], ly - os1[f], lz - os2[f]);
            let gap = dx * nx + dy * ny + dz * nz;
            let slide2 = dx * dx + dy * dy + dz * dz - gap * gap;
            let held = (oh0[f] != 0.0) | (oh1[f] != 0.0) | (oh2[f] != 0.0);
            let older = old_age[f].saturating_add(1);
            let keep = holding
                & !p
                & held
                & (older < HOLD_STEPS)
                & (gap <= HOLD_GAP_M)
                & (slide2 <= HOLD_SLIDE_M * HOLD_SLIDE_M);
            // Released: no hold, but the error estimate still leaves this step's motion into
            // the muscle to the constraints (the point falls back and is pushed).
            let released = !p & held & !keep;
            // The old contact's normal in the world: Rᵀ n (R is a rotation).
            let ox = r[0] * nx + r[1] * ny + r[2] * nz;
            let oy = r[3] * nx + r[4] * ny + r[5] * nz;
            let oz = r[6] * nx + r[7] * ny + r[8] * nz;
            let contact = p | keep;
            let (ux, uy, uz) = if p { (wx, wy, wz) } else { (ox, oy, oz) };
            let absorbs = contact | released;
            let holds = holding & contact;
            shape[f] = if here { if contact { k } else { NONE } } else { shape[f] };
            age[f] = if here { if keep { older } else { 0 } } else { age[f] };
            let pick = |new: f32, kept: f32, out: f32| -> f32 {
                if here {
                    if p {
                        new
                    } else if keep {
                        kept
                    } else {
                        0.0
                    }
                } else {
                    out
                }
            };
            s0[f] = pick(lx, os0[f], s0[f]);
            s1[f] = pick(ly, os1[f], s1[f]);
            s2[f] = pick(lz, os2[f], s2[f]);
            m0[f] = pick(px, nx, m0[f]);
            m1[f] = pick(py, ny, m1[f]);
            m2[f] = pick(pz, nz, m2[f]);
            let normal = |u: f32, on: bool, out: f32| -> f32 {
                if here {
                    if on { u } else { 0.0 }
                } else {
                    out
                }
            };
            a0[f] = normal(ux, absorbs, a0[f]);
            a1[f] = normal(uy, absorbs, a1[f]);
            a2[f] = normal(uz, absorbs, a2[f]);
            h0[f] = normal(ux, holds, h0[f]);
            h1[f] = normal(uy, holds, h1[f]);
            h2[f] = normal(uz, holds, h2[f]);
            let first = here & !holding & p & (first_pushed[f] != 0);
            let first_normal = |n: f32, out: f32| -> f32 {
                if first {
                    n
                } else if here {
                    0.0
                } else {
                    out
                }
            };
            f0[f] = first_normal(fn0[f], f0[f]);
            f1[f] = first_normal(fn1[f], f1[f]);
            f2[f] = first_normal(fn2[f], f2[f]);
            held_count += u32::from(here & holds);
            first_count += u32::from(first);
        }
        (held_count as usize, first_count as usize)
    }
}

crate::sim::simd::multiversion! {
    /// For each point, removes from the vector `(x, y, z)` its component along the unit
    /// `(n0, n1, n2)` when that component has the sign of `sign` (`+1`: along `n`, `−1`:
    /// against it); a zero `n` leaves the point alone.
    fn remove_inward(
        n0: &[f32],
        n1: &[f32],
        n2: &[f32],
        x: &mut [f32],
        y: &mut [f32],
        z: &mut [f32],
        sign: f32,
    ) {
        let len = n0.len().min(n1.len()).min(n2.len()).min(x.len()).min(y.len()).min(z.len());
        let (n0, n1, n2) = (&n0[..len], &n1[..len], &n2[..len]);
        let (x, y, z) = (&mut x[..len], &mut y[..len], &mut z[..len]);
        for i in 0..len {
            let along = x[i] * n0[i] + y[i] * n1[i] + z[i] * n2[i];
            let k = if along * sign > 0.0 { along } else { 0.0 };
            x[i] -= k * n0[i];
            y[i] -= k * n1[i];
            z[i] -= k * n2[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::character::{Primitive, ShapeGeometry};
    use crate::pose::Pose;

    /// A unit sphere turned a quarter about Z and moved to `at`.
    fn sphere(at: Vec3) -> ShapeInstance {
        let g = ShapeGeometry::new(Primitive::Sphere { radius_m: 0.05 }, &[]);
        let turn = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        ShapeInstance::new(g, Pose::new(at, turn))
    }

    fn soa(points: &[Vec3]) -> [Vec<f32>; 3] {
        std::array::from_fn(|c| points.iter().map(|p| p[c]).collect())
    }

    fn get(a: &[Vec<f32>; 3], f: usize) -> Vec3 {
        Vec3::new(a[0][f], a[1][f], a[2][f])
    }

    /// One phase over `fat` points: `pushes[f]` is `Some((shape, world direction))` where the
    /// phase pushed point `f` (its full pass in the same direction).
    fn phase(
        old: &ContactState,
        shapes: &[ShapeInstance],
        fat: &[Vec3],
        pushes: &[Option<(u32, Vec3)>],
        holding: bool,
    ) -> ContactState {
        let first: Vec<_> = pushes.iter().map(|p| p.map(|p| p.1)).collect();
        phase_with_first(old, shapes, fat, pushes, &first, holding)
    }

    /// [`phase`] where the full pass pushed point `f` in direction `first[f]`.
    fn phase_with_first(
        old: &ContactState,
        shapes: &[ShapeInstance],
        fat: &[Vec3],
        pushes: &[Option<(u32, Vec3)>],
        first: &[Option<Vec3>],
        holding: bool,
    ) -> ContactState {
        let pushed: Vec<u8> = pushes.iter().map(|p| u8::from(p.is_some())).collect();
        let last_shape: Vec<u32> = pushes.iter().map(|p| p.map_or(0, |p| p.0)).collect();
        let dirs: Vec<Vec3> = pushes
            .iter()
            .map(|p| p.map_or(Vec3::ZERO, |p| p.1))
            .collect();
        let first_pushed: Vec<u8> = first.iter().map(|p| u8::from(p.is_some())).collect();
        let first: Vec<Vec3> = first.iter().map(|p| p.unwrap_or(Vec3::ZERO)).collect();
        let (dirs, fat, first) = (soa(&dirs), soa(fat), soa(&first));
        let mut new = ContactState::default();
        new.update(
            old,
            &PhaseEnd {
                pushed: &pushed,
                last_shape: &last_shape,
                last_normal: &dirs,
                fat_points: &fat,
                shapes,
                first_pushed: &first_pushed,
                first_normal: &first,
            },
            holding,
            &mut ShapeTable::default(),
        );
        new
    }

    #[test]
    fn a_pushed_point_is_held_while_it_rests_where_it_was_pushed() {
        let centre = Vec3::new(0.3, 0.1, -0.2);
        let shapes = [sphere(Vec3::ZERO), sphere(centre)];
        let up = Vec3::Y;
        let on_top = centre + 0.05 * up;
        // Point 0 is pushed onto shape 1's top, point 1 never touches anything.
        let far = Vec3::splat(2.0);
        let s0 = phase(
            &ContactState::default(),
            &shapes,
            &[on_top, far],
            &[Some((1, up)), None],
            true,
        );
        assert_eq!((s0.shape[0], s0.age[0]), (1, 0));
        assert_eq!(s0.shape[1], NONE);
        assert!(get(&s0.hold, 0).abs_diff_eq(up, 1e-6));
        assert_eq!(get(&s0.hold, 1), Vec3::ZERO);
        assert_eq!(
            (s0.held_points(), s0.contact_points(), s0.pushed_points()),
            (1, 1, 1)
        );
        // The contact point and normal are kept in the shape's own (turned) frame.
        let local = shapes[1].shape_from_world.transform_point3(on_top);
        assert!(
            Vec3::from(std::array::from_fn(|c| s0.surface_shape[c][0])).abs_diff_eq(local, 1e-6)
        );

        // Resting there (5 µm above, slid 0.5 mm): still held, one step older.
        let rest = on_top + Vec3::new(5e-4, 5e-6, 0.0);
        let s1 = phase(&s0, &shapes, &[rest, far], &[None, None], true);
        assert_eq!((s1.shape[0], s1.age[0]), (1, 1));
        assert!(get(&s1.hold, 0).abs_diff_eq(up, 1e-5));
        // Sinking in is not a reason to let go (the constraints push it out).
        let sunk = phase(
            &s1,
            &shapes,
            &[on_top - 1e-3 * up, far],
            &[None, None],
            true,
        );
        assert_eq!(sunk.held_points(), 1);

        // Lifted off past the gap, slid past the limit, or held too long: released. The
        // released point keeps its normal for the error estimate, for that one step.
        let lifted = phase(
            &s1,
            &shapes,
            &[on_top + 2.0 * HOLD_GAP_M * up, far],
            &[None, None],
            true,
        );
        let slid = phase(
            &s1,
            &shapes,
            &[on_top + Vec3::X * 1.5 * HOLD_SLIDE_M, far],
            &[None, None],
            true,
        );
        for released in [&lifted, &slid] {
            assert_eq!(released.shape[0], NONE);
            assert_eq!(get(&released.hold, 0), Vec3::ZERO);
            assert!(get(&released.absorb, 0).abs_diff_eq(up, 1e-5));
            assert_eq!(released.held_points(), 0);
        }
        let mut s = s1;
        for _ in 2..HOLD_STEPS {
            s = phase(&s, &shapes, &[on_top, far], &[None, None], true);
            assert_eq!(s.held_points(), 1, "age {}", s.age[0]);
        }
        let aged = phase(&s, &shapes, &[on_top, far], &[None, None], true);
        assert_eq!(aged.held_points(), 0, "released at {HOLD_STEPS} steps");
        // A released point has no contact left to keep.
        let after = phase(&aged, &shapes, &[on_top, far], &[None, None], true);
        assert_eq!(get(&after.absorb, 0), Vec3::ZERO);
    }

    #[test]
    fn the_hold_follows_its_muscle_as_the_skeleton_moves_it() {
        let up = Vec3::Y;
        let before = [sphere(Vec3::ZERO)];
        let s0 = phase(
            &ContactState::default(),
            &before,
            &[0.05 * up],
            &[Some((0, up))],
            true,
        );
        // The muscle turns a quarter about X and moves; the point moved with it.
        let turn = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
        let mut after = before;
        let world_from_shape = Pose::new(Vec3::new(0.0, 0.0, 0.1), turn).mul_pose(&Pose::new(
            Vec3::ZERO,
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
        ));
        after[0] = ShapeInstance::new(after[0].geometry, world_from_shape);
        let moved = after[0]
            .world_from_shape
            .transform_point3(before[0].shape_from_world.transform_point3(0.05 * up));
        let s1 = phase(&s0, &after, &[moved], &[None], true);
        assert_eq!(s1.held_points(), 1);
        let normal = after[0]
            .world_from_shape
            .transform_vector3(before[0].shape_from_world.transform_vector3(up));
        assert!(normal.abs_diff_eq(turn * up, 1e-5));
        assert!(
            get(&s1.hold, 0).abs_diff_eq(normal, 1e-5),
            "{}",
            get(&s1.hold, 0)
        );
        // Left where it was while the muscle moved away: released.
        let s1 = phase(&s0, &after, &[0.05 * up], &[None], true);
        assert_eq!(s1.held_points(), 0);
    }

    #[test]
    fn without_holding_contacts_are_the_last_pushes_alone() {
        let shapes = [sphere(Vec3::ZERO)];
        let up = Vec3::Y;
        let s0 = phase(
            &ContactState::default(),
            &shapes,
            &[0.05 * up],
            &[Some((0, up))],
            false,
        );
        assert_eq!((s0.held_points(), s0.contact_points()), (0, 1));
        assert!(get(&s0.absorb, 0).abs_diff_eq(up, 1e-6));
        let s1 = phase(&s0, &shapes, &[0.05 * up], &[None], false);
        assert_eq!((s1.held_points(), s1.contact_points()), (0, 0));
        assert_eq!(get(&s1.absorb, 0), Vec3::ZERO);
        // A point the full pass pushed along +X and a re-check along +Y: the projection alone
        // leaves the inward error along both to the constraints; holding, the last only.
        let (first, last) = (Some(Vec3::X), Some((0, up)));
        let fat = [0.05 * up];
        let projected = phase_with_first(&s1, &shapes, &fat, &[last], &[first], false);
        let held = phase_with_first(&s1, &shapes, &fat, &[last], &[first], true);
        assert!(get(&projected.absorb_first, 0).abs_diff_eq(Vec3::X, 1e-6));
        assert_eq!(get(&held.absorb_first, 0), Vec3::ZERO);
        let error = |s: &ContactState| {
            let mut e = vec![1.0f32, 2.0, 0.5];
            s.drop_inward_error(&mut e);
            Vec3::from_slice(&e)
        };
        assert_eq!(error(&projected), Vec3::new(0.0, 0.0, 0.5));
        assert_eq!(error(&held), Vec3::new(1.0, 0.0, 0.5));
    }

    #[test]
    fn characters_with_more_shapes_than_a_table_holds_are_taken_in_chunks() {
        let count = 2 * TABLE_SHAPES + 7;
        let shapes: Vec<ShapeInstance> = (0..count)
            .map(|k| sphere(Vec3::new(k as f32, 0.0, 0.0)))
            .collect();
        let up = Vec3::Y;
        let picks = [
            3,
            TABLE_SHAPES - 1,
            TABLE_SHAPES,
            TABLE_SHAPES + 5,
            count - 1,
        ];
        let fat: Vec<Vec3> = picks
            .iter()
            .map(|&k| Vec3::new(k as f32, 0.05, 0.0))
            .collect();
        let pushes: Vec<_> = picks.iter().map(|&k| Some((k as u32, up))).collect();
        let s0 = phase(&ContactState::default(), &shapes, &fat, &pushes, true);
        let s1 = phase(&s0, &shapes, &fat, &vec![None; picks.len()], true);
        for (f, &k) in picks.iter().enumerate() {
            assert_eq!(s0.shape[f], k as u32);
            assert_eq!(
                (s1.shape[f], s1.age[f]),
                (k as u32, 1),
                "point {f} on shape {k}"
            );
            assert!(get(&s1.hold, f).abs_diff_eq(up, 1e-5));
        }
        assert_eq!(s1.held_points(), picks.len());
    }

    #[test]
    fn the_reaction_and_the_absorbed_error_take_only_the_inward_part() {
        let mut s = ContactState::default();
        s.clear(3);
        // Point 0 held with the normal +Y, point 1 with +X, point 2 not held.
        for (f, n) in [(0, Vec3::Y), (1, Vec3::X)] {
            for c in 0..3 {
                s.hold[c][f] = n[c];
                s.absorb[c][f] = n[c];
            }
        }
        // Accelerations: point 0 pressed in and sideways, point 1 pulled away, point 2 pressed.
        let acc = [
            Vec3::new(1.0, -9.81, 2.0),
            Vec3::new(3.0, 1.0, 0.0),
            Vec3::new(0.0, -9.81, 0.0),
        ];
        let mut a: Vec<f32> = (0..3).flat_map(|c| acc.iter().map(move |p| p[c])).collect();
        s.hold(&mut a);
        let at = |a: &[f32], f: usize| Vec3::new(a[f], a[3 + f], a[6 + f]);
        assert_eq!(at(&a, 0), Vec3::new(1.0, 0.0, 2.0));
        assert_eq!(at(&a, 1), acc[1], "a pull away from the muscle stays");
        assert_eq!(at(&a, 2), acc[2], "no contact, no reaction");
        // The error estimate loses the part into the muscle (against the normal is out of it
        // for an acceleration, along the normal is into it for an error: Euler minus Verlet).
        let err = [
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-1.0, 2.0, 0.0),
            Vec3::new(0.0, 5.0, 0.0),
        ];
        let mut e: Vec<f32> = (0..3).flat_map(|c| err.iter().map(move |p| p[c])).collect();
        s.drop_inward_error(&mut e);
        assert_eq!(at(&e, 0), Vec3::new(1.0, 0.0, 3.0));
        assert_eq!(at(&e, 1), err[1]);
        assert_eq!(at(&e, 2), err[2]);
    }
}
