//! Triangle meshes as plain data, and tessellation of the simple shapes the character uses
//! (spheres, superellipsoids, cylinders) from plain parameters. Winding is counter-clockwise seen
//! from outside; normals point outwards. Metres throughout.

use glam::{Mat3, Mat4, Vec3};

/// An indexed triangle mesh with one normal per vertex.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions (metres, in the mesh's own frame).
    pub positions: Vec<Vec3>,
    /// Unit normals, one per position.
    pub normals: Vec<Vec3>,
    /// Three indices per triangle, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
}

/// A mesh whose arrays do not fit together.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MeshError {
    /// `normals.len() != positions.len()`.
    #[error("mesh has {positions} positions but {normals} normals")]
    NormalCount {
        /// Number of positions.
        positions: usize,
        /// Number of normals.
        normals: usize,
    },
    /// The index list is not a whole number of triangles.
    #[error("mesh index count {0} is not a multiple of 3")]
    IndexCount(usize),
    /// An index points past the vertex array.
    #[error("mesh index {index} at position {at} is out of range (only {vertices} vertices)")]
    IndexOutOfRange {
        /// The bad index.
        index: u32,
        /// Where it is in the index list.
        at: usize,
        /// Number of vertices.
        vertices: usize,
    },
}

impl TriMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Checks that normals and indices fit the positions.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.normals.len() != self.positions.len() {
            return Err(MeshError::NormalCount {
                positions: self.positions.len(),
                normals: self.normals.len(),
            });
        }
        if !self.indices.len().is_multiple_of(3) {
            return Err(MeshError::IndexCount(self.indices.len()));
        }
        let vertices = self.positions.len();
        if let Some((at, &index)) = self
            .indices
            .iter()
            .enumerate()
            .find(|&(_, &i)| i as usize >= vertices)
        {
            return Err(MeshError::IndexOutOfRange {
                index,
                at,
                vertices,
            });
        }
        Ok(())
    }

    /// A mesh from positions and triangles, with smooth (area-weighted) vertex normals.
    pub fn from_triangles(positions: Vec<Vec3>, indices: Vec<u32>) -> Self {
        let normals = smooth_normals(&positions, &indices);
        Self {
            positions,
            normals,
            indices,
        }
    }

    /// Recomputes smooth normals from the triangles.
    pub fn recompute_normals(&mut self) {
        self.normals = smooth_normals(&self.positions, &self.indices);
    }

    /// This mesh mapped by `target_from_mesh` (normals by its inverse transpose).
    pub fn transformed(&self, target_from_mesh: Mat4) -> Self {
        let normal_matrix = Mat3::from_mat4(target_from_mesh).inverse().transpose();
        Self {
            positions: self
                .positions
                .iter()
                .map(|&p| target_from_mesh.transform_point3(p))
                .collect(),
            normals: self
                .normals
                .iter()
                .map(|&n| (normal_matrix * n).normalize_or_zero())
                .collect(),
            indices: self.indices.clone(),
        }
    }

    /// A sphere of `radius_m` about the origin; `segments` around (≥3), `rings` pole to pole (≥2).
    pub fn sphere(radius_m: f32, segments: u32, rings: u32) -> Self {
        Self::superellipsoid(Vec3::splat(radius_m), 1.0, 1.0, segments, rings)
    }

    /// A superellipsoid (Barr) about the origin, its axis of revolution +Y.
    ///
    /// `radii_m` are the semi-axes along x, y, z. `exponent_north_south` shapes the profile
    /// along Y and `exponent_east_west` the cross-section in the XZ plane: 1 gives an ellipsoid,
    /// values towards 0 a box, 2 a double cone/diamond. Exponents are clamped to `[0.05, 4]`.
    pub fn superellipsoid(
        radii_m: Vec3,
        exponent_north_south: f32,
        exponent_east_west: f32,
        segments: u32,
        rings: u32,
    ) -> Self {
        let segments = segments.max(3);
        let rings = rings.max(2);
        let e1 = exponent_north_south.clamp(0.05, 4.0);
        let e2 = exponent_east_west.clamp(0.05, 4.0);
        let mut positions = Vec::with_capacity(((rings + 1) * (segments + 1)) as usize);
        let mut normals = Vec::with_capacity(positions.capacity());
        for i in 0..=rings {
            let eta = -std::f32::consts::FRAC_PI_2 + std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..=segments {
                let omega = std::f32::consts::TAU * j as f32 / segments as f32;
                let p = Vec3::new(
                    radii_m.x * signed_cos_pow(eta, e1) * signed_cos_pow(omega, e2),
                    radii_m.y * signed_sin_pow(eta, e1),
                    radii_m.z * signed_cos_pow(eta, e1) * signed_sin_pow(omega, e2),
                );
                let analytic = Vec3::new(
                    signed_cos_pow(eta, 2.0 - e1) * signed_cos_pow(omega, 2.0 - e2) / radii_m.x,
                    signed_sin_pow(eta, 2.0 - e1) / radii_m.y,
                    signed_cos_pow(eta, 2.0 - e1) * signed_sin_pow(omega, 2.0 - e2) / radii_m.z,
                );
                let n = if analytic.is_finite() && analytic.length_squared() > 1e-12 {
                    analytic.normalize()
                } else {
                    // Poles and degenerate radii: fall back to the ellipsoid gradient.
                    (p / (radii_m * radii_m).max(Vec3::splat(1e-12))).normalize_or(Vec3::Y)
                };
                positions.push(p);
                normals.push(n);
            }
        }
        let indices = grid_indices(rings, segments);
        Self {
            positions,
            normals,
            indices,
        }
    }

    /// A capped cylinder of `radius_m` from y = 0 to y = `length_m` (a bone from its joint along
    /// the bone's +Y); `segments` around (≥3).
    pub fn cylinder(radius_m: f32, length_m: f32, segments: u32) -> Self {
        let segments = segments.max(3);
        let mut mesh = Self::default();
        // Side: two rings, normals radial.
        for (ring, y) in [0.0, length_m].into_iter().enumerate() {
            let _ = ring;
            for j in 0..=segments {
                let omega = std::f32::consts::TAU * j as f32 / segments as f32;
                let radial = Vec3::new(omega.cos(), 0.0, omega.sin());
                mesh.positions.push(radial * radius_m + Vec3::Y * y);
                mesh.normals.push(radial);
            }
        }
        mesh.indices = grid_indices(1, segments);
        // Caps: a centre vertex and their own rim (flat normals).
        for (y, normal) in [(0.0, -Vec3::Y), (length_m, Vec3::Y)] {
            let centre = mesh.positions.len() as u32;
            mesh.positions.push(Vec3::Y * y);
            mesh.normals.push(normal);
            for j in 0..=segments {
                let omega = std::f32::consts::TAU * j as f32 / segments as f32;
                mesh.positions
                    .push(Vec3::new(omega.cos() * radius_m, y, omega.sin() * radius_m));
                mesh.normals.push(normal);
            }
            for j in 0..segments {
                let a = centre + 1 + j;
                let b = a + 1;
                if normal.y > 0.0 {
                    mesh.indices.extend_from_slice(&[centre, b, a]);
                } else {
                    mesh.indices.extend_from_slice(&[centre, a, b]);
                }
            }
        }
        mesh
    }

    /// A cylinder between two points (for thin bones): `None` when the points coincide or are
    /// not finite.
    pub fn cylinder_between(a: Vec3, b: Vec3, radius_m: f32, segments: u32) -> Option<Self> {
        let world_from_bone = frame_along(a, b)?;
        let length_m = (b - a).length();
        Some(Self::cylinder(radius_m, length_m, segments).transformed(world_from_bone))
    }

    /// An open tube through the points of `path` (at least 2, consecutive points distinct),
    /// radius per point; used for the reference scene's skin-like shape.
    pub fn tube(path: &[Vec3], radii_m: &[f32], segments: u32) -> Self {
        let segments = segments.max(3);
        let mut mesh = Self::default();
        if path.len() < 2 || radii_m.len() != path.len() {
            return mesh;
        }
        let mut reference = Vec3::X;
        for (i, (&p, &r)) in path.iter().zip(radii_m).enumerate() {
            let tangent = if i == 0 {
                path[1] - path[0]
            } else if i + 1 == path.len() {
                path[i] - path[i - 1]
            } else {
                path[i + 1] - path[i - 1]
            }
            .normalize_or(Vec3::Y);
            // Parallel transport of the reference axis keeps the rings from twisting.
            let side = (reference - tangent * reference.dot(tangent))
                .normalize_or(tangent.any_orthonormal_vector());
            reference = side;
            let other = tangent.cross(side);
            for j in 0..=segments {
                let omega = std::f32::consts::TAU * j as f32 / segments as f32;
                let radial = side * omega.cos() - other * omega.sin();
                mesh.positions.push(p + radial * r);
                mesh.normals.push(radial);
            }
        }
        mesh.indices = grid_indices(path.len() as u32 - 1, segments);
        mesh
    }
}

impl TriMesh {
    /// A skin grid of `around × along` points (index `j·around + i`, periodic in `i`, open in
    /// `j`), triangulated with smooth normals. Triangles face away from each row's centroid
    /// (outwards for a tube-like skin). `None` when the sizes do not fit.
    pub fn periodic_grid(positions: &[Vec3], around: u32, along: u32) -> Option<Self> {
        let (m, n) = (around as usize, along as usize);
        if m < 3 || n < 2 || positions.len() != m * n {
            return None;
        }
        let mut indices = Vec::with_capacity(m * (n - 1) * 6);
        for j in 0..n - 1 {
            for i in 0..m {
                let a = (j * m + i) as u32;
                let b = (j * m + (i + 1) % m) as u32;
                let c = ((j + 1) * m + i) as u32;
                let d = ((j + 1) * m + (i + 1) % m) as u32;
                indices.extend_from_slice(&[a, c, b, b, c, d]);
            }
        }
        let mut mesh = Self::from_triangles(positions.to_vec(), indices);
        // Orient outwards: compare normals with the direction from the row's centroid.
        let mut score = 0.0f32;
        for j in 0..n {
            let row = &positions[j * m..(j + 1) * m];
            let centroid = row.iter().copied().sum::<Vec3>() / m as f32;
            for (k, p) in row.iter().enumerate() {
                score += mesh.normals[j * m + k].dot(*p - centroid);
            }
        }
        if score < 0.0 {
            for tri in mesh.indices.chunks_exact_mut(3) {
                tri.swap(1, 2);
            }
            for n in &mut mesh.normals {
                *n = -*n;
            }
        }
        Some(mesh)
    }
}

/// A rigid frame at `a` whose +Y points to `b` (for placing cylinders along segments).
pub fn frame_along(a: Vec3, b: Vec3) -> Option<Mat4> {
    let d = b - a;
    if !a.is_finite() || !b.is_finite() || d.length_squared() < 1e-18 {
        return None;
    }
    let y = d.normalize();
    let rotation = glam::Quat::from_rotation_arc(Vec3::Y, y);
    Some(Mat4::from_rotation_translation(rotation, a))
}

/// Area-weighted smooth normals; vertices without any triangle (or degenerate ones) get +Y.
pub fn smooth_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let (Some(&pa), Some(&pb), Some(&pc)) =
            (positions.get(a), positions.get(b), positions.get(c))
        else {
            continue;
        };
        let n = (pb - pa).cross(pc - pa);
        if !n.is_finite() {
            continue;
        }
        sums[a] += n;
        sums[b] += n;
        sums[c] += n;
    }
    sums.into_iter().map(|n| n.normalize_or(Vec3::Y)).collect()
}

/// Indices of a (rows+1) × (cols+1) vertex grid, row-major, counter-clockwise with rows going
/// along the surface's "up" and columns around it.
fn grid_indices(rows: u32, cols: u32) -> Vec<u32> {
    let stride = cols + 1;
    let mut indices = Vec::with_capacity((rows * cols * 6) as usize);
    for i in 0..rows {
        for j in 0..cols {
            let a = i * stride + j;
            let b = (i + 1) * stride + j;
            let c = i * stride + j + 1;
            let d = (i + 1) * stride + j + 1;
            indices.extend_from_slice(&[a, b, c, c, b, d]);
        }
    }
    indices
}

/// `sign(x)·|x|^e`, with |x| below 1e-6 snapped to 0: `cos(π/2)` is −4e-8 in f32, and a small
/// exponent would turn that into a visible, inside-out ring at the poles.
fn signed_pow(x: f32, exponent: f32) -> f32 {
    if x.abs() < 1e-6 {
        0.0
    } else {
        x.signum() * x.abs().powf(exponent)
    }
}

fn signed_cos_pow(angle: f32, exponent: f32) -> f32 {
    signed_pow(angle.cos(), exponent)
}

fn signed_sin_pow(angle: f32, exponent: f32) -> f32 {
    signed_pow(angle.sin(), exponent)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every triangle's geometric normal agrees with its vertices' normals and points away from
    /// the origin (for closed shapes around it).
    fn assert_outward(mesh: &TriMesh, centre: Vec3) {
        mesh.validate().expect("valid mesh");
        let mut checked = 0;
        for tri in mesh.indices.chunks_exact(3) {
            let p: Vec<Vec3> = tri.iter().map(|&i| mesh.positions[i as usize]).collect();
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let shortest = (p[1] - p[0])
                .length()
                .min((p[2] - p[1]).length())
                .min((p[0] - p[2]).length());
            if shortest < 1e-5 {
                continue; // pole triangles are degenerate
            }
            let mid = (p[0] + p[1] + p[2]) / 3.0;
            assert!(n.dot(mid - centre) > 0.0, "inward triangle {tri:?}");
            let vn = tri
                .iter()
                .map(|&i| mesh.normals[i as usize])
                .fold(Vec3::ZERO, |a, b| a + b);
            assert!(
                vn.dot(n) > 0.0,
                "vertex normals disagree with winding at {tri:?}"
            );
            checked += 1;
        }
        assert!(checked > 0);
    }

    #[test]
    fn sphere_is_outward_and_on_radius() {
        let s = TriMesh::sphere(0.5, 16, 8);
        assert_outward(&s, Vec3::ZERO);
        for p in &s.positions {
            assert!((p.length() - 0.5).abs() < 1e-5);
        }
    }

    #[test]
    fn boxy_superellipsoid_stays_inside_its_radii_and_outward() {
        let radii = Vec3::new(0.1, 0.3, 0.2);
        let s = TriMesh::superellipsoid(radii, 0.2, 0.3, 24, 12);
        assert_outward(&s, Vec3::ZERO);
        for (p, n) in s.positions.iter().zip(&s.normals) {
            assert!(p.abs().cmple(radii + Vec3::splat(1e-5)).all(), "{p}");
            assert!((n.length() - 1.0).abs() < 1e-4);
        }
        // Boxy: some vertex is near a corner of the bounding box in x and z at the equator.
        assert!(
            s.positions
                .iter()
                .any(|p| p.x > 0.09 && p.z > 0.17 && p.y.abs() < 0.01)
        );
    }

    #[test]
    fn cylinder_spans_its_length_and_is_closed_outward() {
        let c = TriMesh::cylinder(0.05, 0.4, 12);
        let centre = Vec3::new(0.0, 0.2, 0.0);
        assert_outward(&c, centre);
        let (lo, hi) = c
            .positions
            .iter()
            .fold((f32::MAX, f32::MIN), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        assert_eq!((lo, hi), (0.0, 0.4));
    }

    #[test]
    fn cylinder_between_points_reaches_both_ends() {
        let a = Vec3::new(0.1, 0.2, 0.3);
        let b = Vec3::new(0.5, -0.2, 0.3);
        let c = TriMesh::cylinder_between(a, b, 0.01, 8).expect("distinct points");
        let near = |q: Vec3| c.positions.iter().any(|p| (*p - q).length() < 1e-5);
        assert!(near(a) && near(b));
        assert!(TriMesh::cylinder_between(a, a, 0.01, 8).is_none());
        assert!(TriMesh::cylinder_between(a, Vec3::NAN, 0.01, 8).is_none());
    }

    #[test]
    fn tube_is_outward_along_its_path() {
        let path: Vec<Vec3> = (0..6)
            .map(|i| Vec3::new(0.0, i as f32 * 0.1, 0.0))
            .collect();
        let t = TriMesh::tube(&path, &[0.1; 6], 12);
        t.validate().expect("valid");
        for tri in t.indices.chunks_exact(3) {
            let p: Vec<Vec3> = tri.iter().map(|&i| t.positions[i as usize]).collect();
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let mid = (p[0] + p[1] + p[2]) / 3.0;
            let axis_point = Vec3::new(0.0, mid.y, 0.0);
            assert!(n.dot(mid - axis_point) > 0.0);
        }
    }

    #[test]
    fn validate_names_the_problem() {
        let mut m = TriMesh::sphere(1.0, 4, 2);
        m.indices.push(9999);
        assert!(matches!(m.validate(), Err(MeshError::IndexCount(_))));
        m.indices.extend_from_slice(&[0, 0]);
        assert!(matches!(
            m.validate(),
            Err(MeshError::IndexOutOfRange { index: 9999, .. })
        ));
        m.normals.pop();
        assert!(matches!(m.validate(), Err(MeshError::NormalCount { .. })));
    }

    #[test]
    fn periodic_grid_faces_outwards_either_way_round() {
        let ring = |y: f32, sign: f32| -> Vec<Vec3> {
            (0..8)
                .map(|i| {
                    let a = sign * std::f32::consts::TAU * i as f32 / 8.0;
                    Vec3::new(a.cos() * 0.1, y, a.sin() * 0.1)
                })
                .collect()
        };
        for sign in [1.0, -1.0] {
            let pts: Vec<Vec3> = (0..4).flat_map(|j| ring(j as f32 * 0.05, sign)).collect();
            let m = TriMesh::periodic_grid(&pts, 8, 4).expect("grid");
            m.validate().expect("valid");
            assert_eq!(m.triangle_count(), 8 * 3 * 2);
            for tri in m.indices.chunks_exact(3) {
                let p: Vec<Vec3> = tri.iter().map(|&i| m.positions[i as usize]).collect();
                let n = (p[1] - p[0]).cross(p[2] - p[0]);
                let mid = (p[0] + p[1] + p[2]) / 3.0;
                assert!(n.dot(Vec3::new(mid.x, 0.0, mid.z)) > 0.0);
            }
        }
        assert!(TriMesh::periodic_grid(&[Vec3::ZERO; 5], 3, 2).is_none());
    }

    #[test]
    fn smooth_normals_of_a_flat_quad_face_up() {
        let positions = vec![
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 1.0),
        ];
        // Counter-clockwise seen from +Y.
        let m = TriMesh::from_triangles(positions, vec![0, 1, 2, 2, 1, 3]);
        for n in &m.normals {
            assert!((*n - Vec3::Y).length() < 1e-6, "{n}");
        }
    }
}
