//! The contact geometry on its own, on the GPU ([`GeometryProbe`], kernels in `cuda/probe.cu`):
//! GJK + overlap (stages 4–5) for given pairs of posed templates and the facet-prism overlap
//! (stage 6) for given body–triangle cases, each evaluated in f64 and in f32 by the same device
//! functions the step uses. It is how the tests hold the kernels, run on a GPU, to
//! `geometry::pair::overlap_pair` and `geometry::clip::prism_overlap_culled`.

use super::error::CudaError;
use super::kernels::{KernelConfig, Precision, compile};
use super::launch::{cfg, ptr};
use super::layout::{ProbeTemplates, TemplateTables, max_face_indices};
use crate::geometry::Overlap;
use crate::shape::ConvexTemplate;
use cudarc::driver::{CudaContext, CudaFunction, CudaStream, PushKernelArg};
use nalgebra::{Isometry3, Vector3};
use std::sync::Arc;

/// The probe kernels' source file.
pub const PROBE_FILE: &str = "probe.cu";

/// A posed body: template index, scale, pose.
#[derive(Clone, Copy, Debug)]
pub struct ProbeBody {
    pub template: usize,
    pub scale: f64,
    pub pose: Isometry3<f64>,
}

/// A pair case: the bodies, and an axis and margin for `axis_separates`.
#[derive(Clone, Copy, Debug)]
pub struct ProbePair {
    pub a: ProbeBody,
    pub b: ProbeBody,
    pub axis: Vector3<f64>,
    pub margin: f64,
}

/// A facet case: the body, the pair-frame origin, and the triangle relative to that origin.
#[derive(Clone, Copy, Debug)]
pub struct ProbeFacet {
    pub body: ProbeBody,
    pub origin: Vector3<f64>,
    pub triangle: [Vector3<f64>; 3],
}

/// One precision's result of a pair case (the fields of `PairGeometry`, with the status code of
/// `cuda/polytope.cuh: GeometryStatus` in place of a Rust error).
#[derive(Clone, Copy, Debug, Default)]
pub struct ProbePairResult {
    pub status: i32,
    pub intersects: bool,
    /// GJK's separating axis for disjoint bodies; zero otherwise.
    pub separating_axis: Vector3<f64>,
    pub overlap: Overlap<f64>,
}

/// One precision's result of a facet case: `facet_prism`'s status (6: degenerate triangle),
/// `prism_overlap_culled`'s status, and the overlap in world coordinates.
#[derive(Clone, Copy, Debug, Default)]
pub struct ProbeFacetResult {
    pub prism_status: i32,
    pub status: i32,
    pub overlap: Overlap<f64>,
}

/// A kernel of `cuda/probe.cu`; each takes the case count, the template table, the cases'
/// inputs and their outputs ([`GeometryProbe`]'s `launch`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ProbeKernel {
    /// GJK and the overlap of posed pairs, in f64 and f32, and `axis_separates`.
    Pairs,
    /// The facet-prism overlap of posed bodies, in f64 and f32.
    Facets,
}

impl ProbeKernel {
    /// The kernel's name in `cuda/probe.cu`.
    fn name(self) -> &'static str {
        match self {
            ProbeKernel::Pairs => "probe_pairs",
            ProbeKernel::Facets => "probe_facets",
        }
    }
}

/// The probe kernels, compiled once for templates of up to `max_vertices` vertices and
/// `max_faces` faces.
pub struct GeometryProbe {
    /// Device name.
    pub device: String,
    stream: Arc<CudaStream>,
    /// The kernels of [`ProbeKernel::Pairs`] and [`ProbeKernel::Facets`].
    pairs: CudaFunction,
    facets: CudaFunction,
    max_vertices: usize,
    max_faces: usize,
    _ctx: Arc<CudaContext>,
}

fn overlap_from(v: &[f64]) -> Overlap<f64> {
    Overlap {
        volume: v[0],
        centroid: Vector3::new(v[1], v[2], v[3]),
        dv_dxb: Vector3::new(v[4], v[5], v[6]),
        moment_b: Vector3::new(v[7], v[8], v[9]),
        depth: v[10],
        thickness: v[11],
    }
}

fn pair_from(v: &[f64]) -> ProbePairResult {
    ProbePairResult {
        status: v[0] as i32,
        intersects: v[1] != 0.0,
        separating_axis: Vector3::new(v[2], v[3], v[4]),
        overlap: overlap_from(&v[5..17]),
    }
}

fn facet_from(v: &[f64]) -> ProbeFacetResult {
    ProbeFacetResult {
        prism_status: v[0] as i32,
        status: v[1] as i32,
        overlap: overlap_from(&v[2..14]),
    }
}

fn push_body(out: &mut Vec<f64>, b: &ProbeBody) {
    let t = b.pose.translation.vector;
    let q = b.pose.rotation.coords;
    out.extend_from_slice(&[
        b.template as f64,
        b.scale,
        t.x,
        t.y,
        t.z,
        q.x,
        q.y,
        q.z,
        q.w,
    ]);
}

impl GeometryProbe {
    /// Compiles `cuda/probe.cu` for GPU `ordinal` with workspaces for templates of up to
    /// `max_vertices` vertices and `max_faces` faces.
    pub fn new(ordinal: usize, max_vertices: usize, max_faces: usize) -> Result<Self, CudaError> {
        let ctx = CudaContext::new(ordinal)?;
        let stream = ctx.default_stream();
        let (major, minor) = ctx.compute_capability()?;
        let config = KernelConfig {
            // The probe evaluates both precisions; this only fills the define.
            precision: Precision::Double,
            walls: false,
            friction: false,
            rolling_friction: false,
            periodic: false,
            spheres: false,
            templates: 1,
            max_vertices,
            max_faces,
            materials: 1,
            ghosts: false,
            face_trajectory: false,
            // The CPU's setting, so that the probe's pairs take the CPU's paths.
            enum_planes: crate::geometry::vertex_enumeration::enum_planes(),
        };
        let ptx = compile(PROBE_FILE, &config, (major * 10 + minor) as u32)?;
        let module = ctx.load_module(ptx)?;
        Ok(GeometryProbe {
            device: ctx.name().unwrap_or_else(|_| format!("GPU {ordinal}")),
            stream,
            pairs: module.load_function(ProbeKernel::Pairs.name())?,
            facets: module.load_function(ProbeKernel::Facets.name())?,
            max_vertices,
            max_faces,
            _ctx: ctx,
        })
    }

    /// Checks the templates against the compiled workspace capacities.
    fn check_capacity(&self, templates: &[&ConvexTemplate]) -> Result<(), CudaError> {
        for t in templates {
            if t.vertices.len() > self.max_vertices || t.faces.len() > self.max_faces {
                return Err(CudaError::ProbeCapacity {
                    template: t.name.clone(),
                    vertices: t.vertices.len(),
                    faces: t.faces.len(),
                    max_vertices: self.max_vertices,
                    max_faces: self.max_faces,
                });
            }
        }
        Ok(())
    }

    /// Runs `kernel` over `n` cases of `stride_in` inputs, returning `stride_out` values each.
    fn launch(
        &self,
        kernel: ProbeKernel,
        templates: &[&ConvexTemplate],
        input: &[f64],
        n: usize,
        stride_out: usize,
    ) -> Result<Vec<f64>, CudaError> {
        self.check_capacity(templates)?;
        let (mv, mf, nt) = (self.max_vertices, self.max_faces, templates.len().max(1));
        let t = TemplateTables::new(templates.iter().copied(), nt, mv, mf);
        let st = &self.stream;
        let d_vertices = st.clone_htod(&t.vertices)?;
        let d_normals = st.clone_htod(&t.normals)?;
        let d_offsets = st.clone_htod(&t.offsets)?;
        let d_counts = st.clone_htod(&t.counts)?;
        let d_radius = st.clone_htod(&t.radius)?;
        let d_face_start = st.clone_htod(&t.face_start)?;
        let d_face_points = st.clone_htod(&t.face_points)?;
        let table = ProbeTemplates {
            vertices: ptr(&d_vertices, st),
            normals: ptr(&d_normals, st),
            offsets: ptr(&d_offsets, st),
            counts: ptr(&d_counts, st),
            radius: ptr(&d_radius, st),
            face_start: ptr(&d_face_start, st),
            face_points: ptr(&d_face_points, st),
            max_vertices: mv as i32,
            max_faces: mf as i32,
            max_face_indices: max_face_indices(mv) as i32,
        };
        let mut padded = input.to_vec();
        if padded.is_empty() {
            padded.push(0.0);
        }
        let d_in = st.clone_htod(&padded)?;
        let mut d_out = st.alloc_zeros::<f64>((n * stride_out).max(1))?;
        let ni = n as i32;
        // SAFETY: `probe_pairs`/`probe_facets` of cuda/probe.cu read `n` cases from `d_in` and
        // write `stride_out` values per case into `d_out`; the template table outlives the launch
        // (the stream is synchronised by the copy back).
        let function = match kernel {
            ProbeKernel::Pairs => &self.pairs,
            ProbeKernel::Facets => &self.facets,
        };
        unsafe {
            st.launch_builder(function)
                .arg(&ni)
                .arg(&table)
                .arg(&d_in)
                .arg(&mut d_out)
                .launch(cfg(n))?;
        }
        let mut out = st.clone_dtoh(&d_out)?;
        out.truncate(n * stride_out);
        Ok(out)
    }

    /// Evaluates the pair cases: for each, the f64 result, the f32 result and the verdict of
    /// `axis_separates`.
    pub fn pairs(
        &self,
        templates: &[&ConvexTemplate],
        cases: &[ProbePair],
    ) -> Result<Vec<(ProbePairResult, ProbePairResult, bool)>, CudaError> {
        let mut input = Vec::with_capacity(cases.len() * 22);
        for c in cases {
            push_body(&mut input, &c.a);
            push_body(&mut input, &c.b);
            input.extend_from_slice(&[c.axis.x, c.axis.y, c.axis.z, c.margin]);
        }
        let out = self.launch(ProbeKernel::Pairs, templates, &input, cases.len(), 35)?;
        Ok(out
            .chunks_exact(35)
            .map(|v| (pair_from(&v[0..17]), pair_from(&v[17..34]), v[34] != 0.0))
            .collect())
    }

    /// Evaluates the facet cases: for each, the f64 and the f32 result.
    pub fn facets(
        &self,
        templates: &[&ConvexTemplate],
        cases: &[ProbeFacet],
    ) -> Result<Vec<(ProbeFacetResult, ProbeFacetResult)>, CudaError> {
        let mut input = Vec::with_capacity(cases.len() * 21);
        for c in cases {
            push_body(&mut input, &c.body);
            input.extend_from_slice(c.origin.as_slice());
            for v in &c.triangle {
                input.extend_from_slice(v.as_slice());
            }
        }
        let out = self.launch(ProbeKernel::Facets, templates, &input, cases.len(), 28)?;
        Ok(out
            .chunks_exact(28)
            .map(|v| (facet_from(&v[0..14]), facet_from(&v[14..28])))
            .collect())
    }
}
