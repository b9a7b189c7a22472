//! Mass properties of a closed triangle mesh by signed tetrahedra, and the principal frame.
//!
//! Each oriented triangle (a, b, c) spans a signed tetrahedron with a reference point r; summing
//! the tetrahedra's volumes, first moments and covariance matrices gives the solid's (Tonon 2004,
//! *J. Math. Stat.* 1(1):8–11; Eberly, "Polyhedral Mass Properties (Revisited)", 2002). The
//! reference point is the vertex mean rather than the origin so that meshes far from the origin
//! do not lose digits to cancellation.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// Volume, centroid and inertia tensor of a homogeneous solid of unit density.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    /// Enclosed volume (positive whichever way the triangles are wound).
    pub volume: f64,
    /// Centre of volume.
    pub centroid: Point3<f64>,
    /// Inertia tensor about the centroid, per unit density: `∫ (|x|² 1 − x xᵀ) dV`.
    pub inertia: Matrix3<f64>,
}

impl MassProperties {
    /// Mass properties of the solid bounded by a closed triangle mesh.
    ///
    /// Tetrahedron (r, a, b, c) with edge vectors A = a − r, B = b − r, C = c − r and
    /// D = A·(B×C): volume D/6, first moment D/24 (A+B+C), covariance
    /// `∫ x xᵀ dV = D/120 (AAᵀ + BBᵀ + CCᵀ + (A+B+C)(A+B+C)ᵀ)` (Tonon 2004, Eq. 6). The covariance
    /// is moved to the centroid by the parallel-axis theorem and turned into the inertia tensor
    /// `I = tr(Cov) 1 − Cov`. A mesh wound inward gives the same (positive) result.
    ///
    /// Returns `None` when an index is out of range, or the volume is zero or not finite: the
    /// caller names the source in its error.
    pub fn from_triangles(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Option<Self> {
        if vertices.is_empty() || triangles.is_empty() {
            return None;
        }
        let r = vertices.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / vertices.len() as f64;
        let mut six_vol = 0.0;
        let mut first = Vector3::zeros(); // Σ D (A+B+C), i.e. 24 × first moment
        let mut cov = Matrix3::zeros(); // Σ D (...), i.e. 120 × covariance about r
        for t in triangles {
            let a = vertices.get(t[0] as usize)?.coords - r;
            let b = vertices.get(t[1] as usize)?.coords - r;
            let c = vertices.get(t[2] as usize)?.coords - r;
            let d = a.dot(&b.cross(&c));
            let s = a + b + c;
            six_vol += d;
            first += d * s;
            cov +=
                d * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
        }
        let mut volume = six_vol / 6.0;
        let offset = first / (24.0 * volume); // centroid − r (sign of D cancels)
        let mut cov_r = cov / 120.0;
        if volume < 0.0 {
            volume = -volume;
            cov_r = -cov_r;
        }
        if !(volume > 0.0 && volume.is_finite()) {
            return None;
        }
        let cov_c = cov_r - volume * offset * offset.transpose();
        let inertia = Matrix3::identity() * cov_c.trace() - cov_c;
        if !inertia.iter().all(|x| x.is_finite()) {
            return None;
        }
        Some(MassProperties {
            volume,
            centroid: Point3::from(r + offset),
            inertia,
        })
    }
}

/// Principal axes of a symmetric inertia tensor: returns `(R, moments)` with the moments ascending
/// and `R`'s columns the corresponding axes (a proper rotation), so that `Rᵀ I R = diag(moments)`.
///
/// Moments equal within `rel_tol × max moment` form a degenerate eigenspace, in which any axes are
/// principal; there the axes are chosen closest to the input axes, so symmetric shapes keep the
/// orientation they were given: all three equal → identity; two equal → the distinct axis from the
/// eigensolver and the first input axis with the largest projection onto the degenerate plane.
pub(crate) fn principal_frame(
    inertia: &Matrix3<f64>,
    rel_tol: f64,
) -> (Matrix3<f64>, Vector3<f64>) {
    let sym = (inertia + inertia.transpose()) * 0.5;
    let eig = SymmetricEigen::new(sym);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let moments = Vector3::new(
        eig.eigenvalues[order[0]],
        eig.eigenvalues[order[1]],
        eig.eigenvalues[order[2]],
    );
    let axis =
        |k: usize| -> Vector3<f64> { sign_fixed(eig.eigenvectors.column(order[k]).into_owned()) };
    let scale = moments.abs().max();
    let eq01 = moments[1] - moments[0] <= rel_tol * scale;
    let eq12 = moments[2] - moments[1] <= rel_tol * scale;
    let (x, y) = if eq01 && eq12 {
        (Vector3::x(), Vector3::y())
    } else if eq01 {
        // Unique axis is the third (largest moment): body z. Body x from the input axes.
        let z = axis(2);
        let x = best_projection(&z);
        (x, z.cross(&x))
    } else if eq12 {
        let x = axis(0);
        (x, best_projection(&x))
    } else {
        (axis(0), axis(1))
    };
    // Gram–Schmidt and z = x × y make the frame exactly right-handed and orthonormal.
    let x = x.normalize();
    let y = (y - x * x.dot(&y)).normalize();
    let z = x.cross(&y);
    (Matrix3::from_columns(&[x, y, z]), moments)
}

/// Flips `v` so that its largest-magnitude component is positive (an eigenvector's sign is
/// arbitrary; this keeps it pointing along the input axis it is closest to).
fn sign_fixed(v: Vector3<f64>) -> Vector3<f64> {
    let k = v.iamax();
    if v[k] < 0.0 { -v } else { v }
}

/// The unit projection, onto the plane normal to unit `u`, of the first input axis (x, y, z) whose
/// projection is longest (ties go to the earlier axis).
fn best_projection(u: &Vector3<f64>) -> Vector3<f64> {
    let mut best = Vector3::zeros();
    let mut best_norm = -1.0;
    for e in [Vector3::x(), Vector3::y(), Vector3::z()] {
        let p = e - u * u.dot(&e);
        let n = p.norm();
        if n > best_norm + 1e-12 {
            best = p / n;
            best_norm = n;
        }
    }
    best
}
