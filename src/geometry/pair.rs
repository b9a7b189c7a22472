//! The pair query: the narrow phase and the overlap of two placed templates (the pipeline's
//! stages 4–5 for one pair; seed paper Alg. I for GJK), in one arithmetic or in the GPU's mixed
//! precision. The overlap itself is [`super::overlap`]'s.
//!
//! [`overlap_pair`] places both bodies' planes in a frame at the contact, culls those that
//! cannot bound the overlap, proves an intersection by the Chebyshev centre where it can (GJK
//! decides otherwise), and evaluates the overlap about the centre; [`axis_separates`] is the
//! frame-coherence test that runs before it; [`overlap_pair_mixed`] routes each pair to f32
//! or f64 as the GPU's mixed precision does.

use super::Real;
use super::contained::contained_overlap;
use super::gjk::gjk_separating_axis;
use super::interior::{ChebyshevCentre, chebyshev_centre, chebyshev_centre_wide};
use super::overlap::{Overlap, OverlapError, OverlapWorkspace, overlap_about};
use super::polytope::{Plane, PosedPolytope, set_aside_faces_apart, widen};
use super::quickhull::HullError;
use crate::shape::ConvexTemplate;
use nalgebra::{Isometry3, Vector3};

/// Arithmetic of the pair geometry (`--gpu-precision`): what the GPU's kernels are compiled
/// for, and what the CPU backend evaluates when asked to run as the GPU's mixed precision does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
pub enum Precision {
    /// Everything in f64.
    #[default]
    Double,
    /// f64 state; f32 pair geometry in the pair's contact-centred frame (docs/design.md §3),
    /// with the pairs f32 cannot resolve evaluated in f64 ([`overlap_pair_mixed`]).
    Mixed,
}

/// Buffers for a full pair evaluation: both placed polytopes and the overlap workspace.
#[derive(Clone, Debug, Default)]
pub struct PairWorkspace<T: Real> {
    /// Body A in the pair frame.
    pub a: PosedPolytope<T>,
    /// Body B in the pair frame.
    pub b: PosedPolytope<T>,
    /// Overlap buffers.
    pub overlap: OverlapWorkspace<T>,
}

impl<T: Real> PairWorkspace<T> {
    /// A workspace on the heap.
    pub fn boxed() -> Box<Self> {
        Box::default()
    }

    /// Sets the enumeration's limit of its overlaps ([`OverlapWorkspace::set_enum_planes`]).
    pub fn set_enum_planes(&mut self, n: usize) {
        self.overlap.set_enum_planes(n);
    }
}

/// Contact geometry of one particle pair in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairGeometry {
    /// Narrow-phase (GJK) verdict.
    pub intersects: bool,
    /// For disjoint bodies, GJK's separating axis in world orientation: `v·a > v·b` for every
    /// point `a` of A and `b` of B ([`super::gjk::gjk_separating_axis`]).
    pub separating_axis: Option<Vector3<f64>>,
    /// The overlap, evaluated only when GJK reports an intersection (as in the pipeline).
    pub overlap: Overlap<f64>,
}

impl PairGeometry {
    /// The geometry of a body wholly inside the other ([`super::contained`]).
    fn contained(overlap: Overlap<f64>) -> Self {
        PairGeometry {
            intersects: true,
            separating_axis: None,
            overlap,
        }
    }
}

/// Whether the plane with normal `axis` separates template `ta` (scale `sa`, at `pose_a`) from
/// `tb` by a gap of more than `margin`: `min_A axis·a − max_B axis·b > margin |axis|`. Two support
/// evaluations over the template vertices, in each body's own frame.
///
/// This is the frame-coherence test that runs before GJK: an axis that separated a pair at the
/// last step (GJK's, [`PairGeometry::separating_axis`]) almost always still does. With `margin`
/// above GJK's touching tolerance (about `1e3 ε` times the pair's size in the arithmetic GJK runs
/// in), a pair this test rejects is one GJK would have found disjoint too, so the test changes
/// no result, only the time.
pub fn axis_separates(
    (ta, sa, pose_a): (&ConvexTemplate, f64, &Isometry3<f64>),
    (tb, sb, pose_b): (&ConvexTemplate, f64, &Isometry3<f64>),
    axis: &Vector3<f64>,
    margin: f64,
) -> bool {
    let extreme = |t: &ConvexTemplate, pose: &Isometry3<f64>, sign: f64| {
        let d = pose.rotation.inverse_transform_vector(axis) * sign;
        let mut best = f64::MIN;
        for v in &t.vertices {
            best = best.max(v.coords.dot(&d));
        }
        best
    };
    let min_a = pose_a.translation.vector.dot(axis) - sa * extreme(ta, pose_a, -1.0);
    let max_b = pose_b.translation.vector.dot(axis) + sb * extreme(tb, pose_b, 1.0);
    min_a - max_b > margin * axis.norm()
}

/// Narrow phase and overlap of template `ta` scaled by `sa` at `pose_a` against `tb` at
/// `pose_b`, computed in arithmetic `T` in a frame centred near the contact (docs/design.md §3).
///
/// The planes are culled to those that reach the other body's bounding ball, and the faces
/// that miss the other body are set aside ([`set_aside_faces_apart`]). The Chebyshev centre of
/// what is left is the verdict when it proves an interior (it lies inside the set-aside planes
/// and both bounding balls too, hence inside every plane of both bodies): the bodies intersect
/// and the overlap is evaluated on the planes left, about 5–6 for a dense packing where 12–16
/// reach the other ball. Otherwise GJK (seed Alg. I) decides and gives the separating axis, and
/// an intersection that the centre could not prove (touching or flat) is evaluated on every
/// plane that reaches the other body's ball.
pub fn overlap_pair<T: Real>(
    ws: &mut PairWorkspace<T>,
    a: (&ConvexTemplate, f64, &Isometry3<f64>),
    b: (&ConvexTemplate, f64, &Isometry3<f64>),
) -> Result<PairGeometry, OverlapError> {
    if let Some(overlap) = contained_overlap(a, b) {
        return Ok(PairGeometry::contained(overlap));
    }
    let ((ta, sa, pose_a), (tb, sb, pose_b)) = (a, b);
    let CentredPlanes {
        origin,
        mut centre,
        proven,
    } = centred_planes(ws, a, b, true);
    let separating_axis = if proven {
        None
    } else {
        ws.a.place_vertices(ta, sa, pose_a, &origin);
        ws.b.place_vertices(tb, sb, pose_b, &origin);
        let dir = ws.b.centre - ws.a.centre;
        let axis = gjk_separating_axis(ws.a.vertices(), ws.b.vertices(), dir);
        if axis.is_none() {
            ws.a.restore_aside();
            ws.b.restore_aside();
            centre = chebyshev_centre_wide(ws.a.planes(), ws.b.planes());
        }
        axis
    };
    let intersects = separating_axis.is_none();
    let overlap = if intersects {
        match overlap_in_pair_frame(ws, a, b, &origin, &centre) {
            // GJK finds the bodies touching within its tolerance and the LP no interior
            // thicker than its own (64 ulps of the pair's size): the dual of an overlap that
            // thin spans less than three dimensions to f64, and the bodies touch with no
            // volume. (A cube pile once stopped on such a pair: inscribed radius 2e-17 m, 1.7e-15
            // of the pair's size.)
            Err(OverlapError::Hull(HullError::Degenerate)) if !proven => Overlap::default(),
            result => result?,
        }
    } else {
        Overlap::default()
    };
    Ok(PairGeometry {
        intersects,
        separating_axis: separating_axis.map(|v| widen(&v)),
        overlap,
    })
}

/// The first half of [`overlap_pair`]: the frame origin near the contact, the planes placed,
/// culled and set aside in `ws`, the Chebyshev centre of those in use, and whether it proves
/// that A ∩ B has an interior.
struct CentredPlanes<T: Real> {
    origin: Vector3<f64>,
    centre: ChebyshevCentre<T>,
    proven: bool,
}

fn centred_planes<T: Real>(
    ws: &mut PairWorkspace<T>,
    (ta, sa, pose_a): (&ConvexTemplate, f64, &Isometry3<f64>),
    (tb, sb, pose_b): (&ConvexTemplate, f64, &Isometry3<f64>),
    wide_lp: bool,
) -> CentredPlanes<T> {
    // Frame origin on the centre line where the bounding spheres would touch: near the contact,
    // so that the planes that bound the overlap pass close to the origin and their f32 offsets
    // and normals carry round-off proportional to the overlap's size, not the particles'.
    let (xa, xb) = (pose_a.translation.vector, pose_b.translation.vector);
    let (ra, rb) = (ta.circumscribed_radius * sa, tb.circumscribed_radius * sb);
    let origin = xa + (xb - xa) * (ra / (ra + rb));
    // The planes only: the vertices are placed when GJK needs them (few pairs).
    ws.a.place_planes(ta, sa, pose_a, &origin);
    ws.b.place_planes(tb, sb, pose_b, &origin);
    // Exact culling first (a plane whose half-space holds the other body's bounding ball bounds
    // nothing), then the faces that miss the other body set aside: what is left is about the
    // planes that bound the overlap, and the LP below runs on those.
    let tol = T::of(64.0) * T::EPSILON * T::of(ra + rb);
    ws.a.retain_planes_reaching(&ws.b.centre, T::of(rb), tol);
    ws.b.retain_planes_reaching(&ws.a.centre, T::of(ra), tol);
    set_aside_faces_apart(
        &mut ws.a,
        (ta, sa, pose_a),
        &mut ws.b,
        (tb, sb, pose_b),
        &origin,
        tol,
    );
    // Start the LP at the frame origin, which is near the contact: its steps are then on the
    // scale of the overlap, and so is their round-off (which matters in f32 when one body is
    // much smaller than the distance between the centres). In mixed precision the LP runs in
    // f64 on the f32 planes ([`chebyshev_centre_wide`]: a face resting on a face).
    // With `wide_lp` false (mixed precision's LP on trial, [`overlap_pair_mixed_with`]) the LP
    // runs in `T` from the origin.
    let centre = if wide_lp {
        chebyshev_centre_wide(ws.a.planes(), ws.b.planes())
    } else {
        chebyshev_centre(ws.a.planes(), ws.b.planes(), Vector3::zeros())
    };
    // A centre strictly inside every plane of both bodies proves that A ∩ B has an interior:
    // the bodies intersect (the narrow-phase verdict, without GJK) and the set-aside planes are
    // redundant. The planes in use hold it by the LP's radius, the set-aside ones are checked,
    // and the planes culled against a ball hold every point of that ball: a centre inside both
    // balls is inside them too.
    let inside = |p: &Plane<T>| p.distance(&centre.point) < -tol;
    let in_ball = |c: &Vector3<T>, r: f64| (centre.point - c).norm_squared() < T::of(r) * T::of(r);
    let proven = centre.radius > tol
        && in_ball(&ws.a.centre, ra)
        && in_ball(&ws.b.centre, rb)
        && ws.a.aside_planes().iter().all(inside)
        && ws.b.aside_planes().iter().all(inside);
    CentredPlanes {
        origin,
        centre,
        proven,
    }
}

/// The second half of [`overlap_pair`]: the overlap of the planes in `ws`, evaluated about the
/// interior point `centre` of the frame at `origin`, in world coordinates.
fn overlap_in_pair_frame<T: Real>(
    ws: &mut PairWorkspace<T>,
    (ta, sa, pose_a): (&ConvexTemplate, f64, &Isometry3<f64>),
    (tb, sb, pose_b): (&ConvexTemplate, f64, &Isometry3<f64>),
    origin: &Vector3<f64>,
    centre: &ChebyshevCentre<T>,
) -> Result<Overlap<f64>, OverlapError> {
    // The frame moved onto the interior point (in f64) before the dual transform: the planes
    // that bound the overlap then have offsets of the overlap's size, so their distances δ keep
    // full relative precision in f32 even for a shallow contact of bodies large compared with it.
    let origin = origin + widen(&centre.point);
    ws.a.reposition_planes(ta, sa, pose_a, &origin);
    ws.b.reposition_planes(tb, sb, pose_b, &origin);
    let enumerate_up_to = ws.overlap.enum_planes;
    Ok(overlap_about(
        &mut ws.overlap,
        ws.a.planes(),
        ws.b.planes(),
        Vector3::zeros(),
        enumerate_up_to,
    )?
    .to_world(&origin))
}

/// Mixed precision evaluates in f64 a pair whose Chebyshev radius (about half its overlap's
/// thickness) is below this many f32 epsilons of `ra + rb`, the sum of the circumscribed radii
/// (`PD_MIXED_WIDE_ULPS` of cuda/polytope.cuh): a radius of 512 ε (ra + rb) is a slab about
/// 1000 f32 ulps of the pair's size thick (1.2e-7 m for 1 mm particles).
pub const MIXED_WIDE_ULPS: f64 = 512.0;

/// Mixed precision evaluates in f64 a pair whose f32 dual hull has a vertex outside one of
/// the planes by more than this fraction of the Chebyshev radius (about half the overlap's
/// thickness): [`OverlapWorkspace::hull_vertex_excess`].
pub const MIXED_VERTEX_SLACK: f64 = 1e-2;

/// The pair geometry of the GPU's mixed precision (`--gpu-precision mixed`; `evaluate_pair`
/// and the lean passes of cuda/contact.cu take the same decisions): [`overlap_pair`] in f32
/// where the Chebyshev centre proves an overlap at least [`MIXED_WIDE_ULPS`] f32 epsilons of
/// the pair's size thick, in f64 otherwise, and in f64 again where the f32 dual hull fails or
/// comes out bent (a vertex outside a plane by more than [`MIXED_VERTEX_SLACK`] of the
/// Chebyshev radius: [`OverlapWorkspace::hull_vertex_excess`]).
///
/// A face resting on a face is an overlap nanometres thick across a face millimetres wide: in
/// f32 its planes are placed to about 1e-7 of the particle size, so a slab thinner than a few
/// hundred ulps has its volume, centroid and moment wrong by tens of per cent (measured on a
/// settled packing, `tests/mixed_flat_contacts.rs`); such pairs are a fraction of a per cent
/// of a packing's contacts. A pair the centre does not prove (touching, or GJK's to decide)
/// goes to f64 too: its overlap, if any, is thin.
pub fn overlap_pair_mixed(
    w32: &mut PairWorkspace<f32>,
    w64: &mut PairWorkspace<f64>,
    a: (&ConvexTemplate, f64, &Isometry3<f64>),
    b: (&ConvexTemplate, f64, &Isometry3<f64>),
) -> Result<PairGeometry, OverlapError> {
    overlap_pair_mixed_with(w32, w64, a, b, true)
}

/// [`overlap_pair_mixed`] with the Chebyshev LP in f64 (`wide_lp`, the default) or in f32
/// (`POLYDEM_MIXED_LP=f32`, on trial; `PD_MIXED_LP_F32` of cuda/pair.cuh). In f32 the LP can
/// stop early in the thin wedge of a face resting on a face; its centre then lies nanometres
/// from a face, a radius below [`MIXED_WIDE_ULPS`], and the pair goes to f64 all the same.
pub fn overlap_pair_mixed_with(
    w32: &mut PairWorkspace<f32>,
    w64: &mut PairWorkspace<f64>,
    a: (&ConvexTemplate, f64, &Isometry3<f64>),
    b: (&ConvexTemplate, f64, &Isometry3<f64>),
    wide_lp: bool,
) -> Result<PairGeometry, OverlapError> {
    if let Some(overlap) = contained_overlap(a, b) {
        return Ok(PairGeometry::contained(overlap));
    }
    let ((ta, sa, _), (tb, sb, _)) = (a, b);
    let (ra, rb) = (ta.circumscribed_radius * sa, tb.circumscribed_radius * sb);
    let CentredPlanes {
        origin,
        centre,
        proven,
    } = centred_planes(w32, a, b, wide_lp);
    let wide_below = MIXED_WIDE_ULPS * f64::from(f32::EPSILON) * (ra + rb);
    if !(proven && f64::from(centre.radius) >= wide_below) {
        return overlap_pair(w64, a, b);
    }
    match overlap_in_pair_frame(w32, a, b, &origin, &centre) {
        // A hull that round-off bent: its vertices lie outside the planes.
        Ok(overlap)
            if w32.overlap.hull_vertex_excess().f64() > MIXED_VERTEX_SLACK * overlap.depth =>
        {
            overlap_pair(w64, a, b)
        }
        Ok(overlap) => Ok(PairGeometry {
            intersects: true,
            separating_axis: None,
            overlap,
        }),
        Err(OverlapError::Hull(
            HullError::Degenerate | HullError::Topology | HullError::CapacityExceeded,
        )) => overlap_pair(w64, a, b),
        Err(e) => Err(e),
    }
}
