// Stages 3–7 on the GPU: per pair, the bounding-sphere broad phase, last step's separating axis,
// GJK and the dual-space overlap (overlap.cuh), the contact law (contact_law.cuh) with the
// tangential spring carried in pair slots; per particle, the wall contacts (prism.cuh, in
// wall_contacts.cuh, included at the end). The GPU twin of `Simulation::pair_stage` in
// src/pipeline/pairs.rs and `wall_stage` in src/pipeline/walls.rs; the reduction
// (stage 8) is fused with the half kick in integrate.cu. One thread per pair, per particle–facet
// (the wall prism overlaps) or per particle;
// each thread's geometry workspace is sized by the scene's largest template
// (PD_MAX_TEMPLATE_VERTICES/FACES), so a dodecahedron scene pays for 20 vertices and 12 faces.
#include "common.cuh"
#include "state.cuh"
#include "pair.cuh"
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
// A contact flag (pair `contact`, `wall_contact`) of a contact whose geometry failed, with the
// status in its low byte: the host names the failure of the smallest global ids among those
// flagged (backend/cuda/forces.rs geometry_error, pipeline/error.rs FailureKey), as the CPU
// does, whatever the device's particle order. A live contact's flag is 1.
#define PD_CONTACT_FAILED 0x100u

// Records a geometry error for the host: of all errors of a step, the one of the smallest key
// (source, index, status), pairs before walls as the CPU evaluates them, whatever the order in
// which the threads reach this. error[0..2] hold the bitwise complement of that key as one
// 64-bit word (0: none), so that atomicMax keeps the smallest key (CudaSimulation::forces).
PD_DEVICE void report_error(unsigned int* error, unsigned long long source, int status, unsigned int where) {
    unsigned long long key = (source << 40) | ((unsigned long long)where << 8) | (unsigned long long)(status & 0xff);
    atomicMax((unsigned long long*)error, ~key);
}

// Pair k's cached separating axis (zero: none), kept in float: it is a hint, which
// cached_axis_separates tests with a margin far above GJK's tolerance before it skips GJK, so a
// rounded axis changes which pairs skip GJK at most, never a verdict (an axis rounded to zero,
// or beyond float's range, is no hint: GJK runs). 12 bytes a pair instead of 24.
PD_DEVICE void store_axis(const PairArgs& q, size_t k, V3<double> a) {
    q.axes[3 * k] = (float)a.x;
    q.axes[3 * k + 1] = (float)a.y;
    q.axes[3 * k + 2] = (float)a.z;
}

PD_DEVICE V3<double> load_axis(const PairArgs& q, size_t k) {
    return v3((double)q.axes[3 * k], (double)q.axes[3 * k + 1], (double)q.axes[3 * k + 2]);
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
        store_axis(q, k, zero3<double>());
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
    params.rolling_friction = pm.rolling_friction;
    params.damping = pm.damping;
    params.rocking = !PD_SPHERES;
    params.trajectory = PD_FACE_TRAJECTORY;
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
    kin.inverse_mass_a = 1.0 / p.mass[a];
    kin.inverse_mass_b = 1.0 / p.mass[b];
    kin.split_a = mass_share(p.contacts[a]);
    kin.split_b = mass_share(p.contacts[b]);
#if PD_SPHERES
    // The lens's centroid is on the line of centres: no lever arm, no rotational term.
    kin.effective_mass = 1.0 / (1.0 / p.mass[a] + 1.0 / p.mass[b]);
    kin.dashpot_mass = 1.0 / (kin.split_a / p.mass[a] + kin.split_b / p.mass[b]);
#else
    double area = norm(ov.dv_dxb);
    if (area > 0.0) {
        V3<double> nrm = (-ov.dv_dxb) / area;
        double inverse = 0.0, split = 0.0;
        double term_a = inverse_mass_term(p.mass[a], ia, qa, xa, ov.centroid, nrm);
        inverse += term_a;
        split += kin.split_a * term_a;
        double term_b = inverse_mass_term(p.mass[b], ib, qb, xb, ov.centroid, nrm);
        inverse += term_b;
        split += kin.split_b * term_b;
        kin.effective_mass = 1.0 / inverse;
        kin.dashpot_mass = 1.0 / split;
    } else {
        kin.effective_mass = min_(p.mass[a], p.mass[b]);
        kin.dashpot_mass = min_(p.mass[a] / kin.split_a, p.mass[b] / kin.split_b);
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
    V3<double> axis = load_axis(q, k);
    double reach = q.p.radius[a] + q.p.radius[b];
    return !(axis == zero3<double>()) && axis_separates(A, B, axis, 1e-9 * reach);
}

// Stages 4–5 finished: the geometry status of pair k and its overlap. Returns whether the pair
// goes on to the contact law (errors are reported, the separating axis or its absence kept for
// the next step, the slots of a pair without contact cleared).
PD_DEVICE bool pair_geometry_outcome(const PairArgs& q, size_t k, int status, const PairGeometry& g) {
    if (status != STATUS_OK) {
        report_error(q.error, PD_ERROR_PAIR, status, (unsigned int)k);
        store_axis(q, k, zero3<double>());
        clear_pair(q, k);
        q.out.contact[k] = PD_CONTACT_FAILED | (unsigned int)(status & 0xff);
        return false;
    }
    if (g.overlap.volume <= 0.0) {
        store_axis(q, k, g.separating_axis);
        clear_pair(q, k);
        return false;
    }
    store_axis(q, k, zero3<double>());
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
#if PD_DOUBLE_GEOMETRY
    int status = overlap_pair_t<GeomReal, true>(ws, A, B, &g);
#else
    // Mixed precision (pair.cuh overlap_pair_mixed, geometry::pair::overlap_pair_mixed).
    PairWorkspace<double> wide;
    int status = overlap_pair_mixed(ws, wide, A, B, &g);
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
// pair_faces: its planes in staged[k − first], its bucket (by plane count) in
// bucket[k − first], counted in bucket_count (the staging buffers hold one batch of pairs,
// src/backend/cuda/pair_contacts.rs). Pairs needing GJK or the dual hull are appended to `deferred` (count in
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
            // Mixed precision sends the pairs f32 cannot resolve to the full evaluation, in f64.
            int status = pair_planes_t<GeomReal, false, !PD_DOUBLE_GEOMETRY>(ws, A, B, &g, &frame, &ready);
            int m = ws.a.n_planes + ws.b.n_planes;
            if (status == STATUS_DEFERRED || status == STATUS_WIDE ||
                (status == STATUS_OK && ready && m > PD_ENUM_MAX_PLANES)) {
                append(deferred, deferred_count, (unsigned int)kk);
            } else if (status == STATUS_OK && ready) {
                StagedPlanes& s = staged[k - (size_t)first];
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
    bucket[k - (size_t)first] = key < 0 ? (unsigned char)PD_PLANE_BUCKETS : (unsigned char)key;
    // One atomic per bucket and warp: the lanes of a bucket add together.
    unsigned int lanes = __match_any_sync(__activemask(), key);
    int leader = __ffs(lanes) - 1;
    if (key >= 0 && (int)(threadIdx.x & 31u) == leader) {
        atomicAdd(&bucket_count[key], (unsigned int)__popc(lanes));
    }
#endif
}

// Between the lean passes: the staged pairs of first .. n_pairs − 1 listed bucket by bucket in
// `order` by their index in the list (bucket_count from pair_planes, bucket[k − first] its
// buckets; bucket_fill zeroed by the host). Within a bucket the
// order is that of the atomics, which changes no result: each pair writes only its own slots.
extern "C" __global__ void bucket_pairs(int first, int n_pairs, const unsigned char* bucket,
                                        const unsigned int* bucket_count, unsigned int* bucket_fill,
                                        unsigned int* order) {
    int kk = first + (int)(blockIdx.x * blockDim.x + threadIdx.x);
    if (kk >= n_pairs) {
        return;
    }
    int key = bucket[kk - first];
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
// to the deferred list. Launched for every pair of the range first .. (the batch pair_planes
// staged), the threads past the staged count return at once.
extern "C" __global__ void PD_PAIR_BOUNDS pair_faces(int first, PairArgs args, const unsigned int* order,
                                                    const unsigned int* bucket_count, const StagedPlanes* staged,
                                                    unsigned int* deferred, unsigned int* deferred_count) {
#if PD_SPHERES
    (void)first;
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
    const StagedPlanes& s = staged[k - (size_t)first];
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

#include "wall_contacts.cuh"
