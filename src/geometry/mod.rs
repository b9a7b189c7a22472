//! Exact contact geometry between convex polyhedra and wall facets.
//!
//! Every query here has an f64 reference instance and an f32 instance (the arithmetic type is a
//! [`Real`]); the GPU kernels in `cuda/` are twins of these functions. Pair geometry is computed in
//! a frame centred near the pair (docs/design.md §3), which is what makes f32 viable.
//!
//! - [`gjk`]: GJK intersection test (seed paper Alg. I).
//! - [`interior`]: the Chebyshev centre of the intersection, the robust interior point the dual
//!   transform needs.
//! - [`quickhull`]: incremental Quickhull in fixed-capacity buffers (seed Alg. III–V).
//! - [`overlap`]: overlap volume, centroid, `S = dV/dx_B` and the torque moment (seed Alg. II–VI,
//!   Eq. 4–9; Feng, Han & Owen 2012 for `S`).
//! - [`clip`]: polyhedron against a triangle facet (seed Alg. VII, Sutherland–Hodgman).
//! - [`polytope`]: a template placed in a pair frame (vertices and face planes).
//! - [`vertex_enumeration`]: the overlap's faces by vertex enumeration, the exact alternative to
//!   the dual hull for the few planes a culled pair keeps.
//! - [`sphere`]: the sphere fast path: lens and cap overlaps in closed form.

pub mod clip;
pub mod contained;
pub mod gjk;
pub mod interior;
pub mod overlap;
pub mod pair;
pub mod polytope;
pub mod quickhull;
mod real;
pub mod sphere;
pub mod vertex_enumeration;

pub use clip::{FacetContact, facet_contact, section_polygon, sutherland_hodgman};
pub use gjk::gjk_intersect;
pub use interior::{ChebyshevCentre, chebyshev_centre, chebyshev_centre_wide};
pub use overlap::{Overlap, OverlapError, OverlapWorkspace, overlap_volume};
pub use pair::{PairGeometry, PairWorkspace, overlap_pair};
pub use polytope::{Plane, PosedPolytope};
pub use real::{Real, portable_cbrt, portable_exp, portable_ln, portable_pow, portable_sin_cos};
