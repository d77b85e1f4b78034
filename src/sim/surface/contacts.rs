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
//! - the fat point is more than [`HOLD_GAP_M`] (0.1 mm) off the muscle's tangent plane there
//!   (the muscle moved away, or the point lifted off),
//! - it slid more than [`HOLD_SLIDE_M`] along that plane (a plane is only close to a curved
//!   surface near where it touches: `t² / 2R` off it at a distance `t`, 25 µm at 1 mm on a
//!   2 cm radius), or
//! - [`HOLD_STEPS`] steps passed since the push (this also bounds what the frame check does not
//!   see: a muscle's joint-tied taper, twist and bend).
//!
//! A released point falls back onto the muscle under the full forces and is pushed again,
//! which renews its contact.
//!
//! Everything is kept per free point in structure-of-arrays form. The pushes record their
//! contact in the pushing shape's frame as they are made (`super::constraints`), so after a
//! phase ([`ContactState::update`]) only the held points that were not pushed again are looked
//! at one by one (their fat point mapped into their shape's frame); the rest of the bookkeeping
//! and the integrator's two uses ([`ContactState::hold`], [`ContactState::drop_inward_error`])
//! are single vectorised passes over the free points.

use glam::Vec3;

use super::constraints::Pushes;
use super::masks::collect_hits;
use crate::character::ShapeInstance;

/// Steps a contact holds its point after the push that made it (the push's own step counts
/// as the first).
pub const HOLD_STEPS: u8 = 8;
/// Largest distance of a held point's fat point off the muscle's tangent plane at its contact,
/// metres. The fat point `r − τ n̂` moves with the skin's normal: at τ = 1 cm a turn of 1 mrad,
/// from neighbours moving, shifts it by 10 µm. At the 10 µm projection tolerance 39 % of the
/// torso's checks released their point for that alone, and those points fell back and made
/// 46 % of all pushes; at 0.1 mm the torso's pushes per step fall by 23 % (316 to 242 over 10 s
/// of its motion), with the same step counts and depths. A point held up to 0.1 mm above its
/// muscle is a float of a tenth of a millimetre for a few steps at most.
pub const HOLD_GAP_M: f32 = 1.0e-4;
/// Largest distance a held point may slide along that tangent plane from its contact, metres.
pub const HOLD_SLIDE_M: f32 = 1.0e-3;

/// `shape` of a point without a contact.
const NONE: u32 = u32::MAX;

/// Whether a fat point at `local` (in the frame of its contact's shape) still rests where the
/// push left it: at most [`HOLD_GAP_M`] off the tangent plane through `surface` with the unit
/// normal `normal` (inside is fine: the constraints push it out) and at most [`HOLD_SLIDE_M`]
/// along it.
#[inline(always)]
fn rests_on_plane(local: Vec3, surface: Vec3, normal: Vec3) -> bool {
    let d = local - surface;
    let gap = d.dot(normal);
    let slide2 = d.length_squared() - gap * gap;
    (gap <= HOLD_GAP_M) & (slide2 <= HOLD_SLIDE_M * HOLD_SLIDE_M)
}

/// Per free point: the contact the constraint phase left it in. Part of the model's state, so a
/// snapshot or checkpoint continues exactly as the run it was taken from.
#[derive(Debug, Default, PartialEq)]
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
    /// step's reaction ([`ContactState::hold`]). Read only while `held` is not 0 (a state written
    /// with holding off leaves these arrays as its buffer had them).
    hold: [Vec<f32>; 3],
    /// World unit normal of every point pushed in the last step, held, or released in it, zero
    /// elsewhere: the next step's error estimate leaves the inward error along it to the
    /// constraints ([`ContactState::drop_inward_error`]).
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

impl Clone for ContactState {
    fn clone(&self) -> Self {
        let mut c = Self::default();
        c.clone_from(self);
        c
    }

    /// Field by field into the existing arrays: the model saves a checkpoint of its contacts
    /// every few steps, and the derived `clone_from` would allocate every array anew.
    fn clone_from(&mut self, source: &Self) {
        self.shape.clone_from(&source.shape);
        self.age.clone_from(&source.age);
        let sources = (source.surface_shape.iter().chain(&source.normal_shape))
            .chain(source.hold.iter().chain(&source.absorb))
            .chain(&source.absorb_first);
        for (to, from) in self.vectors_mut().zip(sources) {
            to.clone_from(from);
        }
        self.held = source.held;
        self.firsts = source.firsts;
    }
}

/// What a constraint phase left at the free points, for [`ContactState::update`].
pub(super) struct PhaseEnd<'a> {
    /// Per free point, non-zero where any pass of the phase pushed the point.
    pub pushed: &'a [u8],
    /// The last push of each point, and the fat points.
    pub pushes: Pushes<'a>,
    /// The shapes of the phase (at the end of its step).
    pub shapes: &'a [ShapeInstance],
    /// With holding off: per free point, non-zero where the phase's full pass pushed the
    /// point, and the world direction of that push (the later passes overwrite the last
    /// push's). Not needed with holding on.
    pub first: Option<(&'a [u8], &'a [Vec<f32>; 3])>,
}

/// The three components of a SoA vector as slices.
fn parts(a: &[Vec<f32>; 3]) -> [&[f32]; 3] {
    a.each_ref().map(Vec::as_slice)
}

/// [`parts`], mutable.
fn parts_mut(a: &mut [Vec<f32>; 3]) -> [&mut [f32]; 3] {
    a.each_mut().map(Vec::as_mut_slice)
}

/// Scratch of [`ContactState::update`].
#[derive(Debug, Clone, Default)]
pub(super) struct UpdateScratch {
    /// Per free point, 1 where a held point was not pushed again (its hold is checked).
    check: Vec<u8>,
    /// Those points, in ascending order.
    checked: Vec<u32>,
    /// Per free point, 1 where the check kept the hold (valid where `check`).
    kept: Vec<u8>,
    /// The checked contacts' world normals (valid where `check`).
    normal: [Vec<f32>; 3],
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
        for a in self.vectors_mut() {
            a.clear();
            a.resize(free, 0.0);
        }
    }

    /// The per-point vectors' components, each a `Vec` over the free points.
    fn vectors_mut(&mut self) -> impl Iterator<Item = &mut Vec<f32>> {
        (self.surface_shape.iter_mut().chain(&mut self.normal_shape))
            .chain(self.hold.iter_mut().chain(&mut self.absorb))
            .chain(&mut self.absorb_first)
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
    /// (The next update would not take the holds up again either: it writes no hold with
    /// holding off.)
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
    /// the error estimate).
    pub fn update(
        &mut self,
        old: &ContactState,
        end: &PhaseEnd<'_>,
        holding: bool,
        scratch: &mut UpdateScratch,
    ) {
        let free = end.pushed.len();
        let p = &end.pushes;
        let sized = |a: &[Vec<f32>; 3]| a.iter().all(|c| c.len() >= free);
        let first_ok = end
            .first
            .is_none_or(|(mask, normal)| mask.len() >= free && sized(normal));
        let inputs_ok = [p.normal, p.surface_shape, p.normal_shape, p.fat_points]
            .into_iter()
            .all(sized)
            && p.shape.len() >= free
            && first_ok;
        if !inputs_ok {
            self.clear(free);
            return;
        }
        self.shape.resize(free, NONE);
        self.age.resize(free, 0);
        for a in self.vectors_mut() {
            a.resize(free, 0.0);
        }
        if !holding {
            // The projection alone: the contacts are this phase's pushes, nothing is held (the
            // hold arrays are not read while `held` is 0), and the contact points in the shapes'
            // frames are not needed.
            self.held = 0;
            self.firsts = projection_pass(
                end.pushed,
                p.shape,
                parts(p.normal),
                end.first.map(|(mask, normal)| (mask, parts(normal))),
                &mut self.shape,
                &mut self.age,
                parts_mut(&mut self.absorb),
                parts_mut(&mut self.absorb_first),
            );
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
        old.check_holds(end, scratch);
        // Holding: no full-pass directions (`absorb_first` is not read while `firsts` is 0).
        self.firsts = 0;
        self.held = update_pass(
            (end.pushed, &scratch.check, &scratch.kept),
            p.shape,
            [
                parts(p.normal),
                parts(p.surface_shape),
                parts(p.normal_shape),
            ],
            parts(&scratch.normal),
            (&old.shape, &old.age),
            [parts(&old.surface_shape), parts(&old.normal_shape)],
            (&mut self.shape, &mut self.age),
            [
                parts_mut(&mut self.surface_shape),
                parts_mut(&mut self.normal_shape),
            ],
            [parts_mut(&mut self.hold), parts_mut(&mut self.absorb)],
        );
    }

    /// The checks of the module docs for every point this state holds that the phase did not
    /// push again, one by one (each maps its fat point into its own shape's frame): into
    /// `scratch`, per free point, whether it was checked, whether its hold is kept, and its
    /// contact's world normal.
    fn check_holds(&self, end: &PhaseEnd<'_>, scratch: &mut UpdateScratch) {
        let free = end.pushed.len();
        // A state that holds nothing may keep old hold normals from before holding was switched
        // off (they are not read while `held` is 0).
        let holding = self.held > 0;
        let [h0, h1, h2] = &self.hold;
        let (h0, h1, h2, pushed) = (&h0[..free], &h1[..free], &h2[..free], &end.pushed[..free]);
        scratch.check.resize(free, 0);
        mark_checks(h0, h1, h2, pushed, holding, &mut scratch.check);
        collect_hits(&scratch.check, &mut scratch.checked);
        scratch.kept.resize(free, 0);
        for c in &mut scratch.normal {
            c.resize(free, 0.0);
        }
        // Every array sliced to the free points once, so the loop's indexing needs no checks
        // (`checked` lists indices below `free`).
        let [q0, q1, q2] = end.pushes.fat_points;
        let (q0, q1, q2) = (&q0[..free], &q1[..free], &q2[..free]);
        let [s0, s1, s2] = &self.surface_shape;
        let (s0, s1, s2) = (&s0[..free], &s1[..free], &s2[..free]);
        let [m0, m1, m2] = &self.normal_shape;
        let (m0, m1, m2) = (&m0[..free], &m1[..free], &m2[..free]);
        let (shape, age) = (&self.shape[..free], &self.age[..free]);
        let kept = &mut scratch.kept[..free];
        let [w0, w1, w2] = &mut scratch.normal;
        let (w0, w1, w2) = (&mut w0[..free], &mut w1[..free], &mut w2[..free]);
        for &f in &scratch.checked {
            let f = f as usize;
            // No such shape any more: released, with no direction to keep.
            let (keep, world) = match end.shapes.get(shape[f] as usize) {
                None => (false, Vec3::ZERO),
                Some(s) => {
                    let local = s
                        .shape_from_world
                        .transform_point3(Vec3::new(q0[f], q1[f], q2[f]));
                    let surface = Vec3::new(s0[f], s1[f], s2[f]);
                    let normal = Vec3::new(m0[f], m1[f], m2[f]);
                    let young = age[f].saturating_add(1) < HOLD_STEPS;
                    let keep = young & rests_on_plane(local, surface, normal);
                    (keep, s.world_from_shape.transform_vector3(normal))
                }
            };
            kept[f] = u8::from(keep);
            (w0[f], w1[f], w2[f]) = (world.x, world.y, world.z);
        }
    }

    /// The contact reaction: removes `min(a·n, 0) n` from the acceleration `a` (SoA
    /// `[x…, y…, z…]` over the free points) of every held point, so its muscle bears what
    /// presses it in.
    pub fn hold(&self, a: &mut [f32]) {
        let free = a.len() / 3;
        if self.held == 0 || !self.sized(free) {
            return;
        }
        let [a0, a1, a2] = super::forces::blocks_mut(a, free);
        let [n0, n1, n2] = &self.hold;
        remove_inward(n0, n1, n2, a0, a1, a2, -1.0);
    }

    /// Removes `max(e·n, 0) n` from the error `e` (SoA `[x…, y…, z…]` over the free points) of
    /// each point with a contact of the last step, held or just released, along its contact
    /// normal (and, with holding off, along its full-pass push): the step went further into
    /// the muscle than Euler's, and the constraint phase replaces that motion (checked against
    /// ε_c, section 4.2.3).
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

/// Per free point: whether a pass of the phase pushed it, whether its hold was checked, and
/// whether the check kept it (`kept` is valid only where `check` is set), each 0 or 1.
type Flags<'a> = (&'a [u8], &'a [u8], &'a [u8]);

crate::sim::simd::multiversion! {
    /// [`ContactState::update`] with holding on, for every free point at once, with selects
    /// only so the loops vectorise; returns how many points it holds. Per point: a push of
    /// this phase makes a new contact from the push's record (`push_shape`, and `push`: its
    /// world direction, its landing point and its direction in the pushing shape's frame); a
    /// checked hold is kept, one step older, where the check kept it (with the world normal
    /// the check found, `check_normal`), and is released otherwise, keeping its normal for one
    /// step of the error estimate. `old` are the contacts' shapes and ages and (`old_contact`)
    /// their points and normals in their shapes' frames; `out` and `contact` (points, normals)
    /// and `normals` (hold, absorb) are the new state's arrays.
    fn update_pass(
        flags: Flags<'_>,
        push_shape: &[u32],
        push: [[&[f32]; 3]; 3],
        check_normal: [&[f32]; 3],
        old: (&[u32], &[u8]),
        old_contact: [[&[f32]; 3]; 2],
        out: (&mut [u32], &mut [u8]),
        contact: [[&mut [f32]; 3]; 2],
        normals: [[&mut [f32]; 3]; 2],
    ) -> usize {
        let (pushed, check, kept) = flags;
        let ((old_shape, old_age), (shape, age)) = (old, out);
        let n = (pushed.len().min(check.len()).min(kept.len()))
            .min(push_shape.len().min(old_shape.len()).min(old_age.len()))
            .min(shape.len().min(age.len()));
        let (pushed, check, kept, push_shape) =
            (&pushed[..n], &check[..n], &kept[..n], &push_shape[..n]);
        let (old_shape, old_age) = (&old_shape[..n], &old_age[..n]);
        let (shape, age) = (&mut shape[..n], &mut age[..n]);
        // Short loops over arrays of one element width each: as one loop over all of them the
        // compiler left it scalar (about 70 instructions a point, 4.6 % of the torso's
        // instructions).
        for f in 0..n {
            let keep = (check[f] & kept[f]) != 0;
            age[f] = if keep { old_age[f].saturating_add(1) } else { 0 };
        }
        let mut held_count = 0u32;
        for f in 0..n {
            let (p, keep) = (pushed[f] != 0, (check[f] & kept[f]) != 0);
            let kept_shape = if keep { old_shape[f] } else { NONE };
            shape[f] = if p { push_shape[f] } else { kept_shape };
            held_count += u32::from(p | keep);
        }
        let [push_normal, push_surface, push_local_normal] = push;
        let [old_surface, old_normal] = old_contact;
        let [surface, normal] = contact;
        let [hold, absorb] = normals;
        let flags = (pushed, check, kept);
        pick_contacts(flags, push_surface, old_surface, surface);
        pick_contacts(flags, push_local_normal, old_normal, normal);
        // A released point (checked, not kept) keeps its normal for the error estimate.
        contact_normals(flags, false, push_normal, check_normal, absorb);
        contact_normals(flags, true, push_normal, check_normal, hold);
        held_count as usize
    }
}

/// `out = new` where the point was pushed, `old` where its hold was kept, zero elsewhere, per
/// component: a part of [`update_pass`] (inlined into each of its copies).
#[inline(always)]
fn pick_contacts(
    (pushed, check, kept): Flags<'_>,
    new: [&[f32]; 3],
    old: [&[f32]; 3],
    out: [&mut [f32]; 3],
) {
    for ((new, old), out) in new.into_iter().zip(old).zip(out) {
        let n = out.len().min(new.len()).min(old.len()).min(pushed.len());
        let (new, old, out) = (&new[..n], &old[..n], &mut out[..n]);
        let (pushed, check, kept) = (&pushed[..n], &check[..n], &kept[..n]);
        for f in 0..n {
            let keep = (check[f] & kept[f]) != 0;
            let held = if keep { old[f] } else { 0.0 };
            out[f] = if pushed[f] != 0 { new[f] } else { held };
        }
    }
}

/// Per component, a contact's world normal where the point has one: the push's (`pushed`,
/// from `pushes`) or the one its hold check found (`checks`); zero elsewhere. `holds` picks
/// which points: the contacts (pushed or kept, the reaction's `hold`), or every point with a
/// contact this step including the released ones (the error estimate's `absorb`). A part of
/// [`update_pass`] (inlined into each of its copies).
#[inline(always)]
fn contact_normals(
    (pushed, check, kept): Flags<'_>,
    holds: bool,
    pushes: [&[f32]; 3],
    checks: [&[f32]; 3],
    out: [&mut [f32]; 3],
) {
    for ((pushes, checks), out) in pushes.into_iter().zip(checks).zip(out) {
        let n = out
            .len()
            .min(pushes.len())
            .min(checks.len())
            .min(pushed.len());
        let (pushes, checks, out) = (&pushes[..n], &checks[..n], &mut out[..n]);
        let (pushed, check, kept) = (&pushed[..n], &check[..n], &kept[..n]);
        for f in 0..n {
            let p = pushed[f] != 0;
            let from_check = if holds { check[f] & kept[f] } else { check[f] };
            // Both loaded, then blended by bits: written as `if p { pushes[f] } else {
            // checks[f] }` the compiler selected between the two addresses and loaded each
            // lane on its own.
            let take = 0u32.wrapping_sub(u32::from(p));
            let normal = (pushes[f].to_bits() & take) | (checks[f].to_bits() & !take);
            out[f] = if p | (from_check != 0) {
                f32::from_bits(normal)
            } else {
                0.0
            };
        }
    }
}

crate::sim::simd::multiversion! {
    /// [`ContactState::update`] with holding off, for every free point at once: a point the
    /// phase pushed (`pushed`) gets its push's shape and world direction (`push_normal`) in
    /// `absorb`, and, where `first` says the full pass pushed it, that push's direction in
    /// `absorb_first`; every other point gets none. Returns how many points got a full-pass
    /// direction (0 without `first`, when `absorb_first` is left as it is).
    fn projection_pass(
        pushed: &[u8],
        push_shape: &[u32],
        push_normal: [&[f32]; 3],
        first: Option<(&[u8], [&[f32]; 3])>,
        shape: &mut [u32],
        age: &mut [u8],
        absorb: [&mut [f32]; 3],
        absorb_first: [&mut [f32]; 3],
    ) -> usize {
        let n = pushed.len().min(push_shape.len()).min(shape.len()).min(age.len());
        let (pushed, push_shape) = (&pushed[..n], &push_shape[..n]);
        let (shape, age) = (&mut shape[..n], &mut age[..n]);
        for f in 0..n {
            shape[f] = if pushed[f] != 0 { push_shape[f] } else { NONE };
            age[f] = 0;
        }
        masked_copy(pushed, pushed, push_normal, absorb);
        let Some((first_pushed, first_normal)) = first else {
            return 0;
        };
        masked_copy(pushed, first_pushed, first_normal, absorb_first);
        let n = n.min(first_pushed.len());
        let (pushed, first_pushed) = (&pushed[..n], &first_pushed[..n]);
        let mut first_count = 0u32;
        for f in 0..n {
            first_count += u32::from((pushed[f] != 0) & (first_pushed[f] != 0));
        }
        first_count as usize
    }
}

/// Per component, `out = from` where both masks are set, zero elsewhere: a part of
/// [`projection_pass`] (inlined into each of its copies).
#[inline(always)]
fn masked_copy(a: &[u8], b: &[u8], from: [&[f32]; 3], out: [&mut [f32]; 3]) {
    for (from, out) in from.into_iter().zip(out) {
        let n = out.len().min(from.len()).min(a.len()).min(b.len());
        let (from, out, a, b) = (&from[..n], &mut out[..n], &a[..n], &b[..n]);
        for f in 0..n {
            out[f] = if (a[f] != 0) & (b[f] != 0) {
                from[f]
            } else {
                0.0
            };
        }
    }
}

crate::sim::simd::multiversion! {
    /// `check[f] = 1` where point `f` is held (a non-zero hold normal `h*`) and was not pushed
    /// again, with `holding` on; 0 elsewhere.
    fn mark_checks(
        h0: &[f32],
        h1: &[f32],
        h2: &[f32],
        pushed: &[u8],
        holding: bool,
        check: &mut [u8],
    ) {
        let n = h0.len().min(h1.len()).min(h2.len()).min(pushed.len()).min(check.len());
        let (h0, h1, h2, pushed) = (&h0[..n], &h1[..n], &h2[..n], &pushed[..n]);
        let check = &mut check[..n];
        for f in 0..n {
            let held = (h0[f] != 0.0) | (h1[f] != 0.0) | (h2[f] != 0.0);
            check[f] = u8::from(holding & held & (pushed[f] == 0));
        }
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

    /// [`phase`] where the full pass pushed point `f` in direction `first[f]`. The pushes are
    /// recorded in their shape's frame as the constraint stages record them.
    fn phase_with_first(
        old: &ContactState,
        shapes: &[ShapeInstance],
        fat: &[Vec3],
        pushes: &[Option<(u32, Vec3)>],
        first: &[Option<Vec3>],
        holding: bool,
    ) -> ContactState {
        let mut new = ContactState::default();
        phase_into(&mut new, old, shapes, fat, pushes, first, holding);
        new
    }

    /// [`phase_with_first`] into the buffer `new`, whatever it held before.
    fn phase_into(
        new: &mut ContactState,
        old: &ContactState,
        shapes: &[ShapeInstance],
        fat: &[Vec3],
        pushes: &[Option<(u32, Vec3)>],
        first: &[Option<Vec3>],
        holding: bool,
    ) {
        let pushed: Vec<u8> = pushes.iter().map(|p| u8::from(p.is_some())).collect();
        let last_shape: Vec<u32> = pushes.iter().map(|p| p.map_or(0, |p| p.0)).collect();
        let dirs: Vec<Vec3> = pushes
            .iter()
            .map(|p| p.map_or(Vec3::ZERO, |p| p.1))
            .collect();
        let in_frame = |f: usize, point: bool| {
            pushes[f].map_or(Vec3::ZERO, |(k, dir)| {
                let t = &shapes[k as usize].shape_from_world;
                if point {
                    t.transform_point3(fat[f])
                } else {
                    t.transform_vector3(dir)
                }
            })
        };
        let surfaces: Vec<Vec3> = (0..fat.len()).map(|f| in_frame(f, true)).collect();
        let normals: Vec<Vec3> = (0..fat.len()).map(|f| in_frame(f, false)).collect();
        let first_pushed: Vec<u8> = first.iter().map(|p| u8::from(p.is_some())).collect();
        let first: Vec<Vec3> = first.iter().map(|p| p.unwrap_or(Vec3::ZERO)).collect();
        let (dirs, fat, first) = (soa(&dirs), soa(fat), soa(&first));
        let (surfaces, normals) = (soa(&surfaces), soa(&normals));
        new.update(
            old,
            &PhaseEnd {
                pushed: &pushed,
                pushes: Pushes {
                    shape: &last_shape,
                    normal: &dirs,
                    surface_shape: &surfaces,
                    normal_shape: &normals,
                    fat_points: &fat,
                },
                shapes,
                // As the model passes them: with holding off only.
                first: (!holding).then_some((&first_pushed, &first)),
            },
            holding,
            &mut UpdateScratch::default(),
        );
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
    fn a_checkpoint_copy_into_a_used_buffer_is_the_state_itself() {
        let centre = Vec3::new(0.3, 0.1, -0.2);
        let shapes = [sphere(Vec3::ZERO), sphere(centre)];
        let on_top = centre + 0.05 * Vec3::Y;
        let far = Vec3::splat(2.0);
        let state = phase(
            &ContactState::default(),
            &shapes,
            &[on_top, far, Vec3::new(0.0, -0.05, 0.0)],
            &[Some((1, Vec3::Y)), None, Some((0, -Vec3::Y))],
            true,
        );
        assert_eq!(state.held_points(), 2);
        // A buffer of another size with other contents, as a checkpoint's is.
        let mut copy = ContactState::default();
        copy.clear(7);
        copy.surface_shape[1][4] = 1.0;
        copy.held = 3;
        copy.clone_from(&state);
        assert_eq!(copy, state);
        assert_eq!(state.clone(), state);
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
    fn holds_left_in_a_reused_buffer_are_not_taken_up_again() {
        // The model keeps two states and swaps them, so a state written with holding off may
        // sit in a buffer that held points when holding was on.
        let shapes = [sphere(Vec3::ZERO)];
        let (up, fat) = (Vec3::Y, [0.05 * Vec3::Y]);
        let held = phase(
            &ContactState::default(),
            &shapes,
            &fat,
            &[Some((0, up))],
            true,
        );
        assert_eq!(held.held_points(), 1);
        let mut off = held.clone();
        phase_into(&mut off, &held, &shapes, &fat, &[None], &[None], false);
        assert_eq!((off.held_points(), off.contact_points()), (0, 0));
        let mut a = vec![0.0f32, -9.81, 0.0];
        off.hold(&mut a);
        assert_eq!(a, [0.0, -9.81, 0.0], "nothing held, nothing taken away");
        let on = phase(&off, &shapes, &fat, &[None], true);
        assert_eq!(
            on.held_points(),
            0,
            "no hold comes back from the stale buffer"
        );
    }

    #[test]
    fn contacts_name_any_of_many_shapes_and_a_lost_shape_releases() {
        let count = 300;
        let shapes: Vec<ShapeInstance> = (0..count)
            .map(|k| sphere(Vec3::new(k as f32, 0.0, 0.0)))
            .collect();
        let up = Vec3::Y;
        let picks = [3, 255, 256, count - 1];
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
        // The character lost its last shapes (an edit): their holds end.
        let s2 = phase(&s1, &shapes[..200], &fat, &vec![None; picks.len()], true);
        assert_eq!(s2.held_points(), 1);
        assert_eq!(s2.shape[3], NONE);
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
            s.held += 1;
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
