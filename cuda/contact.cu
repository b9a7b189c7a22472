// Stages 3–7 on the GPU: per pair, the bounding-sphere broad phase, last step's separating axis,
// GJK and the dual-space overlap (overlap.cuh), the contact law (contact_law.cuh) with the
// tangential spring carried in pair slots; per particle, the wall contacts (prism.cuh). The GPU
// twin of `Simulation::pair_contacts` and `wall_contacts` in src/pipeline.rs; the reduction
// (stage 8) is fused with the half kick in integrate.cu. One thread per pair, per particle–facet
// (the wall prism overlaps) or per particle;
// each thread's geometry workspace is sized by the scene's largest template
// (PD_MAX_TEMPLATE_VERTICES/FACES), so a dodecahedron scene pays for 20 vertices and 12 faces.
#include "common.cuh"
#include "state.cuh"
#include "overlap.cuh"
#include "prism.cuh"
#include "sphere.cuh"
#include "contact_law.cuh"

using namespace pd;

#if PD_DOUBLE_GEOMETRY
typedef double GeomReal;
#else
typedef float GeomReal;
#endif

// Templates in constant memory (docs/design.md §3), filled by the host after loading the module.
__constant__ double pd_template_vertices[PD_TEMPLATES * PD_MAX_TEMPLATE_VERTICES * 3];
__constant__ double pd_template_normals[PD_TEMPLATES * PD_MAX_TEMPLATE_FACES * 3];
__constant__ double pd_template_offsets[PD_TEMPLATES * PD_MAX_TEMPLATE_FACES];
__constant__ int pd_template_counts[PD_TEMPLATES * 2]; // vertices, faces
__constant__ double pd_template_radius[PD_TEMPLATES];  // circumscribed radius
__constant__ double pd_template_equivalent[PD_TEMPLATES]; // volume-equivalent radius
// Face polygons (TemplateView::face_start, face_points) in global memory: threads of a warp
// read different faces, which constant memory would serialise.
__device__ unsigned short pd_template_face_start[PD_TEMPLATES * (PD_MAX_TEMPLATE_FACES + 1)];
__device__ double pd_template_face_points[PD_TEMPLATES * PD_MAX_TEMPLATE_FACE_INDICES * 3];
// Face corners as vertex bit sets (TemplateView::face_mask), for templates of at most 64 vertices.
__device__ unsigned long long pd_template_face_mask[PD_TEMPLATES * PD_MAX_TEMPLATE_FACES];

PD_DEVICE TemplateView template_view(unsigned int t) {
    TemplateView v;
    v.vertices = pd_template_vertices + (size_t)t * PD_MAX_TEMPLATE_VERTICES * 3;
    v.n_vertices = pd_template_counts[2 * t];
    v.normals = pd_template_normals + (size_t)t * PD_MAX_TEMPLATE_FACES * 3;
    v.offsets = pd_template_offsets + (size_t)t * PD_MAX_TEMPLATE_FACES;
    v.n_faces = pd_template_counts[2 * t + 1];
    v.face_start = pd_template_face_start + (size_t)t * (PD_MAX_TEMPLATE_FACES + 1);
    v.face_points = pd_template_face_points + (size_t)t * PD_MAX_TEMPLATE_FACE_INDICES * 3;
    v.face_mask = PD_MAX_TEMPLATE_VERTICES <= 64 ? pd_template_face_mask + (size_t)t * PD_MAX_TEMPLATE_FACES : nullptr;
    v.circumscribed_radius = pd_template_radius[t];
    return v;
}

// ParticleView, PairOutputs and PairArgs, the structs every pair evaluation reads and writes,
// are in layout.cuh (shared with Rust).

// Where a geometry error happened: a pair of the list, or a particle against the walls.
#define PD_ERROR_PAIR 0ull
#define PD_ERROR_WALL 1ull

// Records a geometry error for the host: of all errors of a step, the one of the smallest key
// (source, index, status), pairs before walls as the CPU evaluates them, whatever the order in
// which the threads reach this. error[0..2] hold the bitwise complement of that key as one
// 64-bit word (0: none), so that atomicMax keeps the smallest key (CudaSimulation::forces).
PD_DEVICE void report_error(unsigned int* error, unsigned long long source, int status, unsigned int where) {
    unsigned long long key = (source << 40) | ((unsigned long long)where << 8) | (unsigned long long)(status & 0xff);
    atomicMax((unsigned long long*)error, ~key);
}

// The slots of pair k with no contact: no force, no energy, no spring. Every pair's slots are
// written once per step, by whichever kernel settles the pair: these zeros, or the contact
// law's results (pair_contact_law). The force slots are 72 bytes apart, so a warp's store to
// them touches a sector per lane: clearing every pair first and then writing the contacts
// doubled the pair kernels' L2 write traffic.
PD_DEVICE void clear_pair(const PairArgs& q, size_t k) {
    for (int c = 0; c < 9; ++c) q.out.forces[9 * k + c] = 0.0;
    q.out.energy[k] = 0.0;
    q.out.contact[k] = 0u;
    store_history(q.spring_out, k, no_history());
}

// Stage 3 for pair k of the list (Simulation::pair_contacts): the centroids
// (the periodic image of B taken from the current centroids by the minimum-image rule, `grid`,
// as the list build does, not from the build's shift: a particle wrapped across a periodic face
// since the build keeps its contacts), and whether the bounding spheres meet.
PD_DEVICE bool pair_broad_phase(const PairArgs& q, size_t k, int* a, int* b, V3<double>* xa, V3<double>* xb) {
    const ParticleView& p = q.p;
    *a = q.pairs[k].x;
    *b = q.pairs[k].y;
    *xa = load3(p.position, *a);
    *xb = load3(p.position, *b);
#if PD_PERIODIC
    *xb = *xb + (displacement(q.grid, *xa, *xb) - (*xb - *xa));
#endif
    V3<double> d = *xb - *xa;
    double reach = p.radius[*a] + p.radius[*b];
    if (norm2(d) >= reach * reach) {
#if !PD_SPHERES
        store3(q.axes, k, zero3<double>());
#endif
        clear_pair(q, k);
        return false;
    }
    return true;
}

// Stage 7 for pair k with overlap `ov` (world frame): the contact law with the tangential
// spring, written to the pair's slots. The poses are read again rather than kept in registers
// through the geometry, which would size every thread's registers by them.
// The stability guard's overlap bound (Simulation::forces_with_history_step): a contact of
// particle i whose volume exceeds `max_overlap` of the smaller particle's volume records the
// smallest such i in error[2] as UINT_MAX − i (0: none), read by the host after the forces.
// A particle's volume is (4π/3) R³ of its volume-equivalent radius (stability::ball_volume).
PD_DEVICE double equivalent_volume(const ParticleView& p, size_t i) {
    double r = pd_template_equivalent[p.tmpl[i]] * p.scale[i];
    return 4.0 / 3.0 * 3.141592653589793 * r * r * r;
}

PD_DEVICE void guard_overlap(unsigned int* error, double ratio, double max_overlap, unsigned int i) {
    if (ratio > max_overlap) {
        atomicMax(&error[2], 0xFFFFFFFFu - i);
    }
}

PD_DEVICE void pair_contact_law(const PairArgs& q, size_t k, int a, int b, const Overlap<double>& ov) {
    const ParticleView& p = q.p;
    const PairOutputs& out = q.out;
    guard_overlap(q.error, ov.volume / min_(equivalent_volume(p, a), equivalent_volume(p, b)), q.max_overlap,
                  (unsigned int)min_(a, b));
    V3<double> xa = load3(p.position, a);
    V3<double> xb = load3(p.position, b);
#if PD_PERIODIC
    xb = xb + (displacement(q.grid, xa, xb) - (xb - xa));
#endif
    unsigned int ma = p.material[a], mb = p.material[b];
    const PairMaterial& pm = q.materials[ma * (unsigned int)q.n_materials + mb];
    ContactParameters params;
    params.normal_stiffness = p.cn[a] + p.cn[b];
    params.tangential_stiffness = p.ct[a] + p.ct[b];
    params.restitution = pm.restitution;
    params.friction = pm.friction;
    params.damping = pm.damping;
    params.rocking = !PD_SPHERES;
    ContactKinematics kin;
    kin.x_a = xa;
    kin.x_b = xb;
    kin.v_a = load3(p.velocity, a);
    kin.v_b = load3(p.velocity, b);
    kin.w_a = load3(p.angular_velocity, a);
    kin.w_b = load3(p.angular_velocity, b);
    Quat<double> qa = load_quat(p.orientation, a), qb = load_quat(p.orientation, b);
    V3<double> ia = load3(p.inertia, a), ib = load3(p.inertia, b);
    kin.q_a = qa;
    kin.q_b = qb;
    kin.inverse_inertia_a = v3(1.0 / ia.x, 1.0 / ia.y, 1.0 / ia.z);
    kin.inverse_inertia_b = v3(1.0 / ib.x, 1.0 / ib.y, 1.0 / ib.z);
    kin.sphere_radius_a = PD_SPHERES ? p.radius[a] : 0.0;
    kin.sphere_radius_b = PD_SPHERES ? p.radius[b] : 0.0;
#if PD_SPHERES
    // The lens's centroid is on the line of centres: no lever arm, no rotational term.
    kin.effective_mass = 1.0 / (1.0 / p.mass[a] + 1.0 / p.mass[b]);
#else
    double area = norm(ov.dv_dxb);
    if (area > 0.0) {
        V3<double> nrm = (-ov.dv_dxb) / area;
        double inverse = 0.0;
        inverse += inverse_mass_term(p.mass[a], ia, qa, xa, ov.centroid, nrm);
        inverse += inverse_mass_term(p.mass[b], ib, qb, xb, ov.centroid, nrm);
        kin.effective_mass = 1.0 / inverse;
    } else {
        kin.effective_mass = min_(p.mass[a], p.mass[b]);
    }
#endif
    // The whole history is read with or without friction: the damping's reference speed is
    // part of it.
    ContactHistoryRecord history = load_history(q.spring_in, k);
    ContactForces f = contact_forces(params, pm, ov, kin, &history, q.dt);
    store3(out.forces, 3 * k, f.force_b);
    store3(out.forces, 3 * k + 1, f.torque_a);
    store3(out.forces, 3 * k + 2, f.torque_b);
    out.energy[k] = f.elastic_energy;
    out.contact[k] = 1u;
    store_history(q.spring_out, k, history);
}

#if !PD_SPHERES
// The two bodies of pair k (templates, scales, poses), B at the image `xb`.
PD_DEVICE void pair_bodies(const PairArgs& q, int a, int b, V3<double> xa, V3<double> xb, BodyRef* A, BodyRef* B) {
    const ParticleView& p = q.p;
    A->tpl = template_view(p.tmpl[a]);
    A->scale = p.scale[a];
    A->pos = xa;
    A->rot = load_quat(p.orientation, a);
    B->tpl = template_view(p.tmpl[b]);
    B->scale = p.scale[b];
    B->pos = xb;
    B->rot = load_quat(p.orientation, b);
}

// Stage 4 shortcut: last step's separating axis, with a margin far above GJK's touching
// tolerance, so the verdict is GJK's.
PD_DEVICE bool cached_axis_separates(const PairArgs& q, size_t k, const BodyRef& A, const BodyRef& B, int a, int b) {
    V3<double> axis = load3(q.axes, k);
    double reach = q.p.radius[a] + q.p.radius[b];
    return !(axis == zero3<double>()) && axis_separates(A, B, axis, 1e-9 * reach);
}

// Stages 4–5 finished: the geometry status of pair k and its overlap. Returns whether the pair
// goes on to the contact law (errors are reported, the separating axis or its absence kept for
// the next step, the slots of a pair without contact cleared).
PD_DEVICE bool pair_geometry_outcome(const PairArgs& q, size_t k, int status, const PairGeometry& g) {
    if (status != STATUS_OK) {
        report_error(q.error, PD_ERROR_PAIR, status, (unsigned int)k);
        store3(q.axes, k, zero3<double>());
        clear_pair(q, k);
        return false;
    }
    if (g.overlap.volume <= 0.0) {
        store3(q.axes, k, g.separating_axis);
        clear_pair(q, k);
        return false;
    }
    store3(q.axes, k, zero3<double>());
    return true;
}
#endif

// Stages 3–7 for pair k of the list (Simulation::pair_contacts) in one pass and in full (GJK
// and the dual hull included): the sphere kernel, and the polyhedral pairs the lean passes
// deferred.
PD_DEVICE void evaluate_pair(const PairArgs& q, size_t k) {
    PD_CLK_START
    int a, b;
    V3<double> xa, xb;
    if (!pair_broad_phase(q, k, &a, &b, &xa, &xb)) {
        return;
    }
#if PD_SPHERES
    // Stages 4–5 for spheres: the lens in closed form (Simulation::pair_contacts).
    Overlap<double> ov = sphere_lens(q.p.radius[a], q.p.radius[b], xb - xa);
    if (!(ov.volume > 0.0)) {
        clear_pair(q, k);
        return;
    }
    ov.centroid = ov.centroid + xa;
#else
    BodyRef A, B;
    pair_bodies(q, a, b, xa, xb, &A, &B);
    if (cached_axis_separates(q, k, A, B, a, b)) {
        clear_pair(q, k);
        return;
    }
    // Stages 4–5: the overlap, with GJK where the Chebyshev centre proves nothing.
    PairWorkspace<GeomReal> ws;
    PairGeometry g;
    PD_CLK(0)
    PD_CLK_COUNT(11)
    int status = overlap_pair_t<GeomReal, true>(ws, A, B, &g);
#if !PD_DOUBLE_GEOMETRY
    // f32 cannot resolve every overlap's dual hull: a thin slab between two faces lying on each
    // other (a stack of cubes, a cube landing flat) puts its two large faces' dual points at
    // 1/δ and the others at ~1/L. Such a pair is evaluated again in f64, the CPU's precision.
    if (status == STATUS_HULL_DEGENERATE || status == STATUS_HULL_TOPOLOGY || status == STATUS_HULL_CAPACITY) {
        PairWorkspace<double> wide;
        status = overlap_pair_t<double, true>(wide, A, B, &g);
    }
#endif
#if defined(PD_PHASE_CLOCKS)
    pd_t = clock64();
#endif
    if (!pair_geometry_outcome(q, k, status, g)) {
        return;
    }
    Overlap<double> ov = g.overlap;
#endif
    pair_contact_law(q, k, a, b, ov);
    PD_CLK(8)
}

#ifdef PD_PAIR_MAX_REGISTERS
#define PD_PAIR_BOUNDS __maxnreg__(PD_PAIR_MAX_REGISTERS)
#else
#define PD_PAIR_BOUNDS
#endif

// Appends `item` to the list `list` whose length is *count.
PD_DEVICE void append(unsigned int* list, unsigned int* count, unsigned int item) { list[atomicAdd(count, 1u)] = item; }

// Stages 3–7 of the sphere fast path for pairs first .. n_pairs − 1, one pass.
extern "C" __global__ void PD_PAIR_BOUNDS pair_contacts(int first, int n_pairs, PairArgs args) {
    int kk = first + (int)(blockIdx.x * blockDim.x + threadIdx.x);
    if (kk >= n_pairs) {
        return;
    }
#if PD_SPHERES
    evaluate_pair(args, (size_t)kk);
#else
    (void)args;
#endif
}

// A polyhedral pair's planes between the two lean passes (pair_planes, pair_faces): at most
// PD_ENUM_MAX_PLANES planes (A's first), in the pair frame about `frame`.
struct StagedPlanes {
    Plane<GeomReal> planes[PD_ENUM_MAX_PLANES];
    double frame[3];
    int na;
    int nb;
};
#ifdef PD_SIZEOF_STAGED_PLANES
static_assert(sizeof(StagedPlanes) == PD_SIZEOF_STAGED_PLANES, "StagedPlanes differs from Rust's layout::staged_planes_bytes");
#endif

// Bucket of a staged plane count: the largest counts first, so that the costliest warps start
// first and the tail of the pass is short.
PD_DEVICE int plane_bucket(int m) { return PD_ENUM_MAX_PLANES - m; }
#define PD_PLANE_BUCKETS (PD_ENUM_MAX_PLANES + 1)

// Lean pass 1 for polyhedral pairs first .. n_pairs − 1 (Simulation::pair_contacts): the broad
// phase, the cached axis, the planes culled and placed about the Chebyshev centre. A pair whose
// intersection the centre proves, with at most PD_ENUM_MAX_PLANES planes, is staged for
// pair_faces: its planes in staged[k], its bucket (by plane count) in bucket[k], counted in
// bucket_count. Pairs needing GJK or the dual hull are appended to `deferred` (count in
// deferred_count[0]) for pair_contacts_deferred: a few per cent of the pairs of a dense packing
// need them, and compiled in here they would size every thread's registers and local memory.
// The faces, whose cost grows as the fourth power of the plane count, run in pass 2 in warps
// of equal counts: here a warp would run at the pace of its largest count.
extern "C" __global__ void PD_PAIR_BOUNDS pair_planes(int first, int n_pairs, PairArgs args, unsigned int* deferred,
                                                     unsigned int* deferred_count, StagedPlanes* staged,
                                                     unsigned char* bucket, unsigned int* bucket_count) {
    int kk = first + (int)(blockIdx.x * blockDim.x + threadIdx.x);
    if (kk >= n_pairs) {
        return;
    }
#if PD_SPHERES
    (void)args;
    (void)deferred;
    (void)deferred_count;
    (void)staged;
    (void)bucket;
    (void)bucket_count;
#else
    PD_CLK_START
    size_t k = (size_t)kk;
    int key = -1; // the pair's bucket, or −1 when it is not staged
    int a, b;
    V3<double> xa, xb;
    if (pair_broad_phase(args, k, &a, &b, &xa, &xb)) {
        BodyRef A, B;
        pair_bodies(args, a, b, xa, xb, &A, &B);
        if (cached_axis_separates(args, k, A, B, a, b)) {
            clear_pair(args, k);
        } else {
            PairWorkspace<GeomReal> ws;
            PairGeometry g;
            V3<double> frame;
            bool ready;
            PD_CLK(0)
            PD_CLK_COUNT(11)
            int status = pair_planes_t<GeomReal, false>(ws, A, B, &g, &frame, &ready);
            int m = ws.a.n_planes + ws.b.n_planes;
            if (status == STATUS_DEFERRED || (status == STATUS_OK && ready && m > PD_ENUM_MAX_PLANES)) {
                append(deferred, deferred_count, (unsigned int)kk);
            } else if (status == STATUS_OK && ready) {
                StagedPlanes& s = staged[k];
                for (int i = 0; i < ws.a.n_planes; ++i) s.planes[i] = ws.a.planes[i];
                for (int i = 0; i < ws.b.n_planes; ++i) s.planes[ws.a.n_planes + i] = ws.b.planes[i];
                s.frame[0] = frame.x;
                s.frame[1] = frame.y;
                s.frame[2] = frame.z;
                s.na = ws.a.n_planes;
                s.nb = ws.b.n_planes;
                key = plane_bucket(m);
            } else {
                pair_geometry_outcome(args, k, status, g);
            }
        }
    }
    bucket[k] = key < 0 ? (unsigned char)PD_PLANE_BUCKETS : (unsigned char)key;
    // One atomic per bucket and warp: the lanes of a bucket add together.
    unsigned int lanes = __match_any_sync(__activemask(), key);
    int leader = __ffs(lanes) - 1;
    if (key >= 0 && (int)(threadIdx.x & 31u) == leader) {
        atomicAdd(&bucket_count[key], (unsigned int)__popc(lanes));
    }
#endif
}

// Between the lean passes: the staged pairs of first .. n_pairs − 1 listed bucket by bucket in
// `order` (bucket_count from pair_planes; bucket_fill zeroed by the host). Within a bucket the
// order is that of the atomics, which changes no result: each pair writes only its own slots.
extern "C" __global__ void bucket_pairs(int first, int n_pairs, const unsigned char* bucket,
                                        const unsigned int* bucket_count, unsigned int* bucket_fill,
                                        unsigned int* order) {
    int kk = first + (int)(blockIdx.x * blockDim.x + threadIdx.x);
    if (kk >= n_pairs) {
        return;
    }
    int key = bucket[kk];
    if (key >= PD_PLANE_BUCKETS) {
        return;
    }
    unsigned int base = 0;
    for (int c = 0; c < key; ++c) base += bucket_count[c];
    unsigned int lanes = __match_any_sync(__activemask(), key);
    int leader = __ffs(lanes) - 1;
    int lane = (int)(threadIdx.x & 31u);
    unsigned int start = 0;
    if (lane == leader) {
        start = atomicAdd(&bucket_fill[key], (unsigned int)__popc(lanes));
    }
    start = __shfl_sync(lanes, start, leader);
    order[base + start + (unsigned int)__popc(lanes & ((1u << lane) - 1u))] = (unsigned int)kk;
}

// Lean pass 2: the faces of the staged pairs, listed by bucket_pairs, by vertex enumeration,
// then the contact law. A pair whose faces do not close (which the dual hull must settle) goes
// to the deferred list. Launched for every pair of the range, the threads past the staged count
// return at once.
extern "C" __global__ void PD_PAIR_BOUNDS pair_faces(PairArgs args, const unsigned int* order,
                                                    const unsigned int* bucket_count, const StagedPlanes* staged,
                                                    unsigned int* deferred, unsigned int* deferred_count) {
#if PD_SPHERES
    (void)args;
    (void)order;
    (void)bucket_count;
    (void)staged;
    (void)deferred;
    (void)deferred_count;
#else
    unsigned int total = 0;
    for (int c = 0; c < PD_PLANE_BUCKETS; ++c) total += bucket_count[c];
    unsigned int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= total) {
        return;
    }
    PD_CLK_START
    size_t k = order[i];
    const StagedPlanes& s = staged[k];
    // The planes are read where they were staged (the overlap reads each once).
    const Plane<GeomReal>* planes = s.planes;
    int na = s.na, nb = s.nb;
    V3<double> frame = v3(s.frame[0], s.frame[1], s.frame[2]);
    OverlapWorkspace<GeomReal> ws;
    PairGeometry g;
    g.intersects = 0;
    g.separating_axis = zero3<double>();
    g.overlap = overlap_zero<double>();
    int status = overlap_of_planes<GeomReal, false>(ws, planes, na, planes + na, nb, frame, &g);
#if defined(PD_PHASE_CLOCKS)
    pd_t = clock64();
#endif
    if (status == STATUS_DEFERRED) {
        append(deferred, deferred_count, (unsigned int)k);
        return;
    }
    if (!pair_geometry_outcome(args, k, status, g)) {
        return;
    }
    int2 ab = args.pairs[k];
    pair_contact_law(args, k, ab.x, ab.y, g.overlap);
    PD_CLK(8)
#endif
}

// The deferred pairs of the lean passes, evaluated in full (GJK and the hull included); a
// grid-stride loop over the count the passes left on the device, so the host launches it
// without reading it. Each pair writes only its own slots, so the order of the list does not
// matter.
extern "C" __global__ void pair_contacts_deferred(PairArgs args, const unsigned int* deferred,
                                                  const unsigned int* deferred_count) {
#if PD_SPHERES
    (void)args;
    (void)deferred;
    (void)deferred_count;
#else
    const unsigned int n = deferred_count[0];
    for (unsigned int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
        evaluate_pair(args, (size_t)deferred[i]);
    }
#endif
}

#if PD_WALLS
// Most grid cells a particle's box may span for the merge of their facet lists in
// `wall_candidates` (27: a box at most one cell wide, plus a skin narrower than the particles,
// spans at most three cells per axis; past it, the walk in id order).
#ifndef PD_WALL_MERGE_CELLS
#define PD_WALL_MERGE_CELLS 27
#endif

// WallInfo (one wall mesh in its own frame) and WallState (a wall's pose and velocity field at
// the current time) are in layout.cuh (shared with Rust).

// Point–triangle distance (wall.rs point_triangle_distance, Ericson §5.1.5).
PD_DEVICE double point_triangle_distance(V3<double> x, const double* t) {
    V3<double> a = v3(t[0], t[1], t[2]), b = v3(t[3], t[4], t[5]), c = v3(t[6], t[7], t[8]);
    V3<double> ab = b - a, ac = c - a, ap = x - a;
    double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return norm(ap);
    V3<double> bp = x - b;
    double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) return norm(bp);
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        double v = d1 / (d1 - d3);
        return norm(ap - ab * v);
    }
    V3<double> cp = x - c;
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) return norm(cp);
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        double w = d2 / (d2 - d6);
        return norm(ap - ac * w);
    }
    double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return norm(bp - (c - b) * w);
    }
    double denom = 1.0 / (va + vb + vc);
    double v = vb * denom, w = vc * denom;
    return norm(ap - (ab * v + ac * w));
}

PD_DEVICE int grid_coord(const WallInfo& w, double x, int k) {
    double c = floor((x - w.grid_min[k]) / w.grid_size);
    if (c - c != 0.0) return 0;
    return c < 0.0 ? 0 : (int)min_(c, (double)(w.dims[k] - 1));
}

// The smallest facet id >= `from` listed in grid cells [ca, cb] of a wall (UINT_MAX: none).
// The walk over a particle's facets when its box spans more cells than the merge of
// `wall_candidates` takes: one scan of the cells per facet, so the facets still come in
// increasing id order (WallMesh::facets_near's order, which fixes the order of the sums).
PD_DEVICE unsigned int next_facet_in_box(const unsigned int* cs, const unsigned int* cell_items, const WallInfo& w,
                                         const int ca[3], const int cb[3], unsigned int from) {
    unsigned int best = 0xffffffffu;
    for (int z = ca[2]; z <= cb[2]; ++z) {
        for (int y = ca[1]; y <= cb[1]; ++y) {
            for (int x = ca[0]; x <= cb[0]; ++x) {
                int cell = (z * w.dims[1] + y) * w.dims[0] + x;
                for (unsigned int m = cs[cell]; m < cs[cell + 1]; ++m) {
                    unsigned int f = cell_items[m];
                    if (f >= from && f < best) best = f;
                }
            }
        }
    }
    return best;
}

// A wall's rotation and translation at the current time.
PD_DEVICE Quat<double> wall_rotation(const WallState& s) {
    Quat<double> q;
    q.x = s.rotation[0];
    q.y = s.rotation[1];
    q.z = s.rotation[2];
    q.w = s.rotation[3];
    return q;
}
PD_DEVICE V3<double> wall_translation(const WallState& s) {
    return v3(s.translation[0], s.translation[1], s.translation[2]);
}

// A particle's pose in a wall's frame: local = wall_pose⁻¹ · pose, in nalgebra's order
// (t = q⁻¹(−t_w) + q⁻¹ x_p).
PD_DEVICE void wall_local_pose(const WallState& s, V3<double> xp, Quat<double> qp, V3<double>* local_t,
                               Quat<double>* local_q) {
    Quat<double> qw = wall_rotation(s);
    V3<double> tw = wall_translation(s);
    *local_t = rotate_inverse(qw, -tw) + rotate_inverse(qw, xp);
    Quat<double> qc;
    qc.w = qw.w;
    qc.x = -qw.x;
    qc.y = -qw.y;
    qc.z = -qw.z;
    local_q->w = qc.w * qp.w - qc.x * qp.x - qc.y * qp.y - qc.z * qp.z;
    local_q->x = qc.w * qp.x + qc.x * qp.w + qc.y * qp.z - qc.z * qp.y;
    local_q->y = qc.w * qp.y - qc.x * qp.z + qc.y * qp.w + qc.z * qp.x;
    local_q->z = qc.w * qp.z + qc.x * qp.y - qc.y * qp.x + qc.z * qp.w;
}

// The wall list (built when due, not every step): per particle, for every wall in order, the
// facets within the bounding radius plus `skin` (WallMesh::facets_near with that reach) in
// increasing id order. With `items` null it only counts them into counts[i]; otherwise it writes
// them from items[offset[i]] as (particle · n_walls + wall, facet), the order in which
// `wall_contacts` sums them. While every particle stays within half the skin of where it was,
// in each wall's frame (`kick_drift`'s wall check and the host's bound on the walls' motion),
// the list holds every facet within the bounding radius, which `wall_facet_overlaps` then picks
// by the same distance test as the CPU's per-step query: the same facets in the same order.
extern "C" __global__ void wall_candidates(WallCandidatesParams args) {
    const int n = args.n;
    const ParticleView& p = args.p;
    const int n_walls = args.n_walls;
    const WallInfo* walls = args.walls;
    const WallState* states = args.states;
    const double* triangles = args.triangles;
    const unsigned int* cell_start = args.cell_start;
    const unsigned int* cell_items = args.cell_items;
    const double skin = args.skin;
    unsigned int* counts = args.counts;
    const unsigned int* offset = args.offset;
    uint2* items = args.items;
    int ii = blockIdx.x * blockDim.x + threadIdx.x;
    if (ii >= n) {
        return;
    }
    size_t i = (size_t)ii;
    V3<double> xp = load3(p.position, i);
    Quat<double> qp = load_quat(p.orientation, i);
    double radius = p.radius[i] + skin;
    unsigned int found = 0;
    for (int k = 0; k < n_walls; ++k) {
        const WallInfo& w = walls[k];
        V3<double> local_t;
        Quat<double> local_q;
        wall_local_pose(states[k], xp, qp, &local_t, &local_q);
        // Facets near (WallMesh::facets_near): grid candidates in id order, each once, within
        // reach.
        V3<double> lo = local_t - v3(radius, radius, radius), hi = local_t + v3(radius, radius, radius);
        double top[3];
        for (int c = 0; c < 3; ++c) top[c] = w.grid_min[c] + (double)w.dims[c] * w.grid_size;
        if (hi.x < w.grid_min[0] || lo.x > top[0] || hi.y < w.grid_min[1] || lo.y > top[1] || hi.z < w.grid_min[2] ||
            lo.z > top[2]) {
            continue;
        }
        int ca[3] = {grid_coord(w, lo.x, 0), grid_coord(w, lo.y, 1), grid_coord(w, lo.z, 2)};
        int cb[3] = {grid_coord(w, hi.x, 0), grid_coord(w, hi.y, 1), grid_coord(w, hi.z, 2)};
        const unsigned int* cs = cell_start + w.cell_offset;
        // The box's cells list their facets in increasing id order (FacetGrid), so a merge of
        // the cells' lists gives the increasing id order of WallMesh::facets_near, each facet
        // once, with no buffer and no sort: per facet, the smallest head among the cells, then
        // every cell whose head it is moves on. A box of more than PD_WALL_MERGE_CELLS cells (a
        // skin wider than the particles) walks the grid in id order instead.
        int spans[3] = {cb[0] - ca[0] + 1, cb[1] - ca[1] + 1, cb[2] - ca[2] + 1};
        int n_cells = spans[0] * spans[1] * spans[2];
        bool merge = n_cells <= PD_WALL_MERGE_CELLS;
        unsigned int at[PD_WALL_MERGE_CELLS > 0 ? PD_WALL_MERGE_CELLS : 1];
        unsigned int end[PD_WALL_MERGE_CELLS > 0 ? PD_WALL_MERGE_CELLS : 1];
        if (merge) {
            for (int c = 0; c < n_cells; ++c) {
                int x = ca[0] + c % spans[0], y = ca[1] + (c / spans[0]) % spans[1], z = ca[2] + c / (spans[0] * spans[1]);
                int cell = (z * w.dims[1] + y) * w.dims[0] + x;
                at[c] = cs[cell];
                end[c] = cs[cell + 1];
            }
        }
        unsigned int from = 0;
        while (true) {
            unsigned int id = 0xffffffffu;
            if (merge) {
                for (int c = 0; c < n_cells; ++c) {
                    if (at[c] < end[c]) id = min(id, cell_items[at[c]]);
                }
                if (id == 0xffffffffu) break;
                for (int c = 0; c < n_cells; ++c) {
                    if (at[c] < end[c] && cell_items[at[c]] == id) ++at[c];
                }
            } else {
                id = next_facet_in_box(cs, cell_items, w, ca, cb, from);
                if (id == 0xffffffffu) break;
                from = id + 1;
            }
            size_t f = (size_t)w.facet_offset + id;
            if (point_triangle_distance(local_t, triangles + 9 * f) > radius) continue;
            if (items) {
                items[offset[i] + found] = make_uint2((unsigned int)(i * (size_t)n_walls + (size_t)k), (unsigned int)f);
            }
            ++found;
        }
    }
    if (!items) counts[i] = found;
}

// Stage 6, first part, per item of the wall list (WallMesh::facets_near's distance test and
// WallMesh::contact's prism overlap): the particle placed in the wall's frame; a facet beyond
// its bounding radius is out of reach (zero volume, which the sum skips, as the CPU never lists
// it); otherwise the particle is clipped by the facet's prism. overlaps[12 m ...] = volume,
// centroid (3), S (3), M (3), depth, thickness, in the wall's frame.
extern "C" __global__ void wall_facet_overlaps(WallOverlapsParams args) {
    const int n_items = args.n_items;
    const uint2* items = args.items;
    const int n_walls = args.n_walls;
    const ParticleView& p = args.p;
    const WallState* states = args.states;
    const double* triangles = args.triangles;
    const double* prisms = args.prisms;
    double* overlaps = args.overlaps;
    unsigned int* error = args.error;
    int mm = blockIdx.x * blockDim.x + threadIdx.x;
    if (mm >= n_items) {
        return;
    }
    size_t m = (size_t)mm;
    uint2 item = items[m];
    size_t i = item.x / (unsigned int)n_walls;
    int k = (int)(item.x % (unsigned int)n_walls);
    size_t f = item.y;
    V3<double> local_t;
    Quat<double> local_q;
    wall_local_pose(states[k], load3(p.position, i), load_quat(p.orientation, i), &local_t, &local_q);
    double* out = overlaps + 12 * m;
    if (point_triangle_distance(local_t, triangles + 9 * f) > p.radius[i]) {
        out[0] = 0.0;
        return;
    }
#if PD_SPHERES
    // The sphere's share of its cap behind the facet (WallMesh::sphere_contact).
    V3<double> tri[3];
    for (int q = 0; q < 3; ++q) tri[q] = load3(triangles + 9 * f, q);
    V3<double> facet_normal = v3(prisms[16 * f], prisms[16 * f + 1], prisms[16 * f + 2]);
    Overlap<double> o = sphere_facet(local_t, p.radius[i], tri, facet_normal);
#else
    PosedPolytope<double> body;
    OverlapWorkspace<double> ws;
    const TemplateView tv = template_view(p.tmpl[i]);
    place(body, tv, p.scale[i], local_t, local_q, zero3<double>());
    Plane<double> prism[4];
    for (int q = 0; q < 4; ++q) {
        prism[q].normal = v3(prisms[16 * f + 4 * q], prisms[16 * f + 4 * q + 1], prisms[16 * f + 4 * q + 2]);
        prism[q].offset = prisms[16 * f + 4 * q + 3];
    }
    Overlap<double> o = overlap_zero<double>();
    // WallMesh::contact: the prism overlap on the planes that can bound it.
    int status = prism_overlap_culled(ws, body, tv, placement(p.scale[i], local_t, local_q, zero3<double>()),
                                      tv.circumscribed_radius * p.scale[i], prism, &o);
    if (status != STATUS_OK) {
        report_error(error, PD_ERROR_WALL, status, item.x); // particle · walls + wall
        o = overlap_zero<double>();
    }
#endif
    out[0] = o.volume;
    store3(out + 1, 0, o.centroid);
    store3(out + 4, 0, o.dv_dxb);
    store3(out + 7, 0, o.moment_b);
    out[10] = o.depth;
    out[11] = o.thickness;
}

// Stage 6, second part, per particle (Simulation::wall_contacts): for every wall, the facet
// overlaps summed in facet-id order into the total penetrating volume (WallMesh::contact) and
// the contact law applied once to the total; the wall's spring per particle and wall.
extern "C" __global__ void wall_contacts(WallContactsParams args) {
    const int n = args.n;
    const ParticleView& p = args.p;
    const int n_walls = args.n_walls;
    const WallState* states = args.states;
    const WallInfo* walls = args.walls;
    const unsigned int* item_offset = args.item_offset;
    const uint2* items = args.items;
    const double* overlaps = args.overlaps;
    const PairMaterial* materials = args.materials;
    const int n_materials = args.n_materials;
    const double* spring_in = args.spring_in;
    double* spring_out = args.spring_out;
    double* wall_force = args.wall_force;
    double* wall_torque = args.wall_torque;
    double* wall_energy = args.wall_energy;
    double* per_wall_force = args.per_wall_force;
    unsigned int* wall_contact = args.wall_contact;
    const double dt = args.dt;
    const double max_overlap = args.max_overlap;
    unsigned int* error = args.error;
    int ii = blockIdx.x * blockDim.x + threadIdx.x;
    if (ii >= n) {
        return;
    }
    size_t i = (size_t)ii;
    V3<double> force = zero3<double>(), torque = zero3<double>();
    double energy = 0.0;
    V3<double> xp = load3(p.position, i);
    Quat<double> qp = load_quat(p.orientation, i);
    unsigned int m = item_offset[i], m_end = item_offset[i + 1];
    for (int k = 0; k < n_walls; ++k) {
        size_t slot = i * (size_t)n_walls + (size_t)k;
        store_history(spring_out, slot, no_history());
        store3(per_wall_force, slot, zero3<double>());
        wall_contact[slot] = 0u;
        const WallInfo& w = walls[k];
        const WallState& s = states[k];
        Overlap<double> total = overlap_zero<double>();
        V3<double> first_moment = zero3<double>();
        V3<double> moment_origin = zero3<double>();
        for (; m < m_end && items[m].x == (unsigned int)slot; ++m) {
            const double* q = overlaps + 12 * (size_t)m;
            Overlap<double> o;
            o.volume = q[0];
            o.centroid = load3(q + 1, 0);
            o.dv_dxb = load3(q + 4, 0);
            o.moment_b = load3(q + 7, 0);
            o.depth = q[10];
            o.thickness = q[11];
            if (o.volume > 0.0) {
                total.volume += o.volume;
                first_moment += o.centroid * o.volume;
                total.dv_dxb += o.dv_dxb;
                moment_origin += o.moment_b + cross(o.centroid, o.dv_dxb);
                total.depth = max_(total.depth, o.depth);
                total.thickness = max_(total.thickness, o.thickness);
            }
        }
        if (!(total.volume > 0.0)) continue;
        Quat<double> qw = wall_rotation(s);
        V3<double> tw = wall_translation(s);
        total.centroid = first_moment / total.volume;
        total.moment_b = moment_origin - cross(total.centroid, total.dv_dxb);
        // To world: centroid = R c + t; S and M rotated.
        Overlap<double> world = total;
        world.centroid = rotate(qw, total.centroid) + tw;
        world.dv_dxb = rotate(qw, total.dv_dxb);
        world.moment_b = rotate(qw, total.moment_b);
        const PairMaterial& pm = materials[p.material[i] * (unsigned int)n_materials + (unsigned int)w.material];
        ContactParameters params;
        params.normal_stiffness = p.cn[i] + 0.0;
        params.tangential_stiffness = p.ct[i] + 0.0;
        params.restitution = pm.restitution;
        params.friction = pm.friction;
        params.damping = pm.damping;
        params.rocking = !PD_SPHERES;
        V3<double> c = world.centroid;
        ContactKinematics kin;
        kin.x_a = xp;
        kin.x_b = c;
        kin.v_a = load3(p.velocity, i);
        V3<double> omega = v3(s.omega[0], s.omega[1], s.omega[2]);
        kin.v_b = v3(s.v0[0], s.v0[1], s.v0[2]) + cross(omega, c - v3(s.origin[0], s.origin[1], s.origin[2]));
        kin.w_a = load3(p.angular_velocity, i);
        kin.w_b = omega;
        V3<double> ip = load3(p.inertia, i);
        Quat<double> identity;
        identity.w = 1.0;
        identity.x = 0.0;
        identity.y = 0.0;
        identity.z = 0.0;
        kin.q_a = qp;
        kin.q_b = identity;
        kin.inverse_inertia_a = v3(1.0 / ip.x, 1.0 / ip.y, 1.0 / ip.z);
        kin.inverse_inertia_b = zero3<double>();
        kin.sphere_radius_a = PD_SPHERES ? p.radius[i] : 0.0;
        kin.sphere_radius_b = 0.0;
        double area = norm(world.dv_dxb);
        if (area > 0.0) {
            V3<double> nrm = (-world.dv_dxb) / area;
            double inverse = 0.0;
            inverse += inverse_mass_term(p.mass[i], ip, qp, xp, c, nrm);
            kin.effective_mass = 1.0 / inverse;
        } else {
            kin.effective_mass = p.mass[i];
        }
        ContactHistoryRecord history = load_history(spring_in, slot);
        ContactForces f = contact_forces(params, pm, world, kin, &history, dt);
        guard_overlap(error, world.volume / equivalent_volume(p, i), max_overlap, (unsigned int)i);
        force -= f.force_b;
        torque += f.torque_a;
        energy += f.elastic_energy;
        store3(per_wall_force, slot, f.force_b);
        store_history(spring_out, slot, history);
        wall_contact[slot] = 1u;
    }
    store3(wall_force, i, force);
    store3(wall_torque, i, torque);
    wall_energy[i] = energy;
}
#endif
