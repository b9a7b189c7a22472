// Host harness for the parity test tests/cuda_geometry_host.rs: runs the CUDA contact-geometry
// headers as plain C++17 on the CPU, in double and in float, on cases written by the test.
//
// Build: c++ -O1 -std=c++17 -ffp-contract=off -I cuda cuda/host/geometry_harness.cpp
// (not -O2: g++ 12.2 dropped a double → float rounding there, see tests/cuda_geometry_host.rs)
// Usage: geometry_harness CASES_FILE      (results on stdout)
//        geometry_harness --mixed CASES_FILE  (each pair through mixed precision's routing,
//                                           overlap_pair_mixed: M lines, no facets)
//        geometry_harness --spheres FILE   (the sphere fast path, sphere.cuh; format below)
//        geometry_harness --law FILE       (portable math and the contact law, contact_law.cuh)
//        geometry_harness --sizes          (workspace sizes in bytes for the compiled capacities)
//
// Input (whitespace-separated tokens; every floating-point number is the 16-hex-digit bit
// pattern of an IEEE double, so that values cross the process boundary exactly):
//   templates N
//     N × { nv, nv × (x y z), nf, nf × (nx ny nz offset k v_1 … v_k), circumscribed_radius }
//     (k decimal vertex indices: the face polygon)
//   pairs N
//     N × { ta sa pa(3) qa(w x y z)  tb sb pb(3) qb(w x y z)  axis(3) margin }
//   facets N
//     N × { t s p(3) q(w x y z) origin(3) tri(9, relative to origin) }
// Output, one line per case, floats as hex bit patterns of doubles (float results widened):
//   M i  {status intersects axis(3) volume centroid(3) S(3) M(3) depth thickness} (--mixed)
//   P i  {status intersects axis(3) volume centroid(3) S(3) M(3) depth thickness} for double,
//        then the same for float, then axis_separates (0/1)
//   F i  {prism_status status volume centroid(3) S(3) M(3) depth thickness} for double, then float
// Sphere input: "lenses N" N × { ra rb d(3) }, then "caps N" N × { c(3) r tri(9) n(3) }; output
//   L i {volume centroid(3) S(3) M(3) depth thickness} and C i {the same}.
// Law input: "sincos N" N × { x }, "cbrt N" N × { x }, "pow N" N × { x y }, "law N" N × { c_n c_t e mu damping ln_e
//   log_norm rocking(1.0/0.0) trajectory(1.0/0.0) volume centroid(3) S(3) M(3) depth thickness  x_a x_b v_a v_b w_a
//   w_b (3 each) m_eff inv_m_a inv_m_b q_a(w x y z) q_b inv_inertia_a(3) inv_inertia_b(3) r_sphere_a r_sphere_b
//   spring(3) approach twist dt }; output S i {sin cos}, R i {cbrt}, P i {ln x, exp y, x^y}, W i {force_b(3) torque_a(3)
//   torque_b(3) energy spring(3) approach twist}.

#include "pair.cuh"
#include "prism.cuh"
#include "sphere.cuh"
#include "contact_law.cuh"

#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

namespace {

struct Template {
    std::vector<double> vertices, normals, offsets;
    std::vector<unsigned short> face_start;
    std::vector<double> face_points;
    std::vector<unsigned long long> face_mask;
    double radius = 0.0;
    pd::TemplateView view() const {
        pd::TemplateView v;
        v.vertices = vertices.data();
        v.n_vertices = int(vertices.size() / 3);
        v.normals = normals.data();
        v.offsets = offsets.data();
        v.n_faces = int(offsets.size());
        v.face_start = face_start.data();
        v.face_points = face_points.data();
        v.face_mask = face_mask.size() == offsets.size() ? face_mask.data() : nullptr;
        v.circumscribed_radius = radius;
        return v;
    }
};

FILE* in = nullptr;

[[noreturn]] void fail(const char* what) {
    std::fprintf(stderr, "geometry_harness: bad input (%s)\n", what);
    std::exit(2);
}

long read_int() {
    long x;
    if (std::fscanf(in, "%ld", &x) != 1) fail("integer");
    return x;
}

double read_f64() {
    char buf[64];
    if (std::fscanf(in, "%63s", buf) != 1) fail("float");
    uint64_t bits = std::strtoull(buf, nullptr, 16);
    double x;
    std::memcpy(&x, &bits, 8);
    return x;
}

void read_word(const char* expect) {
    char buf[64];
    if (std::fscanf(in, "%63s", buf) != 1 || std::strcmp(buf, expect) != 0) fail(expect);
}

pd::V3<double> read_v3() {
    double x = read_f64(), y = read_f64(), z = read_f64();
    return pd::v3(x, y, z);
}

pd::Quat<double> read_quat() {
    pd::Quat<double> q;
    q.w = read_f64();
    q.x = read_f64();
    q.y = read_f64();
    q.z = read_f64();
    return q;
}

void put(double x) {
    uint64_t bits;
    std::memcpy(&bits, &x, 8);
    std::printf(" %016" PRIx64, bits);
}

void put3(pd::V3<double> v) {
    put(v.x);
    put(v.y);
    put(v.z);
}

void put_overlap(const pd::Overlap<double>& o) {
    put(o.volume);
    put3(o.centroid);
    put3(o.dv_dxb);
    put3(o.moment_b);
    put(o.depth);
    put(o.thickness);
}

// Fills a workspace with a non-zero byte pattern before each use: on the GPU a thread's
// workspace is uninitialised local memory, so the geometry must not depend on its contents.
template <class W> void poison(W& ws) { std::memset(static_cast<void*>(&ws), 0xA5, sizeof(W)); }

template <class T> void run_pair(pd::PairWorkspace<T>& ws, const pd::BodyRef& a, const pd::BodyRef& b) {
    poison(ws);
    pd::PairGeometry g;
    int st = pd::overlap_pair(ws, a, b, &g);
    std::printf(" %d %d", st, g.intersects);
    put3(g.separating_axis);
    put_overlap(g.overlap);
}

template <class T>
void run_facet(pd::OverlapWorkspace<T>& ws, pd::PosedPolytope<T>& body, const pd::BodyRef& r, pd::V3<double> origin,
               const pd::V3<double> tri[3]) {
    poison(ws);
    poison(body);
    pd::place(body, r.tpl, r.scale, r.pos, r.rot, origin);
    pd::V3<T> t[3];
    for (int k = 0; k < 3; ++k) t[k] = pd::cast3<T>(tri[k]);
    pd::Plane<T> prism[4];
    int pst = pd::facet_prism(t, prism);
    pd::Overlap<T> o = pd::overlap_zero<T>();
    int st = 0;
    if (pst == pd::STATUS_OK) {
        st = pd::prism_overlap_culled(ws, body, r.tpl, pd::placement(r.scale, r.pos, r.rot, origin),
                                      T(r.tpl.circumscribed_radius * r.scale), prism, &o);
    }
    std::printf(" %d %d", pst, st);
    put_overlap(pd::to_world(o, pd::zero3<double>()));
}

void print_sizes() {
    std::printf("PD_MAX_TEMPLATE_VERTICES %d PD_MAX_TEMPLATE_FACES %d PD_MAX_HULL_POINTS %d PD_MAX_HULL_FACES %d\n",
                PD_MAX_TEMPLATE_VERTICES, PD_MAX_TEMPLATE_FACES, PD_MAX_HULL_POINTS, PD_MAX_HULL_FACES);
    std::printf("sizeof PairWorkspace<double> %zu (PosedPolytope %zu, OverlapWorkspace %zu, DualHull %zu)\n",
                sizeof(pd::PairWorkspace<double>), sizeof(pd::PosedPolytope<double>),
                sizeof(pd::OverlapWorkspace<double>), sizeof(pd::DualHull<double>));
    std::printf("sizeof PairWorkspace<float> %zu (PosedPolytope %zu, OverlapWorkspace %zu, DualHull %zu)\n",
                sizeof(pd::PairWorkspace<float>), sizeof(pd::PosedPolytope<float>),
                sizeof(pd::OverlapWorkspace<float>), sizeof(pd::DualHull<float>));
}

int run_spheres(const char* path) {
    in = std::fopen(path, "r");
    if (!in) {
        std::perror(path);
        return 2;
    }
    read_word("lenses");
    long nl = read_int();
    for (long i = 0; i < nl; ++i) {
        double ra = read_f64(), rb = read_f64();
        pd::V3<double> d = read_v3();
        std::printf("L %ld", i);
        put_overlap(pd::sphere_lens(ra, rb, d));
        std::printf("\n");
    }
    read_word("caps");
    long nc = read_int();
    for (long i = 0; i < nc; ++i) {
        pd::V3<double> c = read_v3();
        double r = read_f64();
        pd::V3<double> tri[3];
        for (int k = 0; k < 3; ++k) tri[k] = read_v3();
        pd::V3<double> n = read_v3();
        std::printf("C %ld", i);
        put_overlap(pd::sphere_facet(c, r, tri, n));
        std::printf("\n");
    }
    std::fclose(in);
    return 0;
}

int run_law(const char* path) {
    in = std::fopen(path, "r");
    if (!in) {
        std::perror(path);
        return 2;
    }
    read_word("sincos");
    long ns = read_int();
    for (long i = 0; i < ns; ++i) {
        double s, c;
        pd::portable_sin_cos(read_f64(), &s, &c);
        std::printf("S %ld", i);
        put(s);
        put(c);
        std::printf("\n");
    }
    read_word("cbrt");
    long nr = read_int();
    for (long i = 0; i < nr; ++i) {
        std::printf("R %ld", i);
        put(pd::portable_cbrt(read_f64()));
        std::printf("\n");
    }
    read_word("pow");
    long np = read_int();
    for (long i = 0; i < np; ++i) {
        double x = read_f64(), y = read_f64();
        std::printf("P %ld", i);
        put(pd::portable_ln(x));
        put(pd::portable_exp(y));
        put(pd::portable_pow(x, y));
        std::printf("\n");
    }
    read_word("law");
    long nw = read_int();
    for (long i = 0; i < nw; ++i) {
        pd::ContactParameters params;
        pd::PairMaterial pm;
        params.normal_stiffness = read_f64();
        params.tangential_stiffness = read_f64();
        pm.restitution = params.restitution = read_f64();
        pm.friction = params.friction = read_f64();
        pm.damping = params.damping = read_f64();
        pm.log_restitution = read_f64();
        pm.log_norm = read_f64();
        params.rocking = read_f64() != 0.0;
        params.trajectory = read_f64() != 0.0;
        pm.rolling_friction = params.rolling_friction = read_f64();
        pd::Overlap<double> o;
        o.volume = read_f64();
        o.centroid = read_v3();
        o.dv_dxb = read_v3();
        o.moment_b = read_v3();
        o.depth = read_f64();
        o.thickness = read_f64();
        pd::ContactKinematics kin;
        kin.x_a = read_v3();
        kin.x_b = read_v3();
        kin.v_a = read_v3();
        kin.v_b = read_v3();
        kin.w_a = read_v3();
        kin.w_b = read_v3();
        kin.effective_mass = read_f64();
        kin.inverse_mass_a = read_f64();
        kin.inverse_mass_b = read_f64();
        kin.q_a = read_quat();
        kin.q_b = read_quat();
        kin.inverse_inertia_a = read_v3();
        kin.inverse_inertia_b = read_v3();
        kin.sphere_radius_a = read_f64();
        kin.sphere_radius_b = read_f64();
        kin.split_a = read_f64();
        kin.split_b = read_f64();
        kin.dashpot_mass = read_f64();
        pd::ContactHistoryRecord h;
        h.spring = read_v3();
        h.approach_speed = read_f64();
        h.twist = read_f64();
        double dt = read_f64();
        pd::ContactForces f = pd::contact_forces(params, pm, o, kin, &h, dt);
        std::printf("W %ld", i);
        put3(f.force_b);
        put3(f.torque_a);
        put3(f.torque_b);
        put(f.elastic_energy);
        put3(h.spring);
        put(h.approach_speed);
        put(h.twist);
        std::printf("\n");
    }
    std::fclose(in);
    return 0;
}

} // namespace

int main(int argc, char** argv) {
    if (argc == 2 && std::strcmp(argv[1], "--sizes") == 0) {
        print_sizes();
        return 0;
    }
    if (argc == 3 && std::strcmp(argv[1], "--spheres") == 0) {
        return run_spheres(argv[2]);
    }
    if (argc == 3 && std::strcmp(argv[1], "--law") == 0) {
        return run_law(argv[2]);
    }
    // --mixed: the same cases, each pair through mixed precision's routing instead.
    const bool mixed = argc == 3 && std::strcmp(argv[1], "--mixed") == 0;
    if (argc != 2 && !mixed) {
        std::fprintf(stderr, "usage: geometry_harness [--mixed] CASES_FILE | --sizes\n");
        return 2;
    }
    const char* path = argv[argc - 1];
    in = std::fopen(path, "r");
    if (!in) {
        std::perror(path);
        return 2;
    }
    read_word("templates");
    long nt = read_int();
    std::vector<Template> templates(nt);
    for (auto& t : templates) {
        long nv = read_int();
        for (long i = 0; i < 3 * nv; ++i) t.vertices.push_back(read_f64());
        long nf = read_int();
        for (long i = 0; i < nf; ++i) {
            for (int k = 0; k < 3; ++k) t.normals.push_back(read_f64());
            t.offsets.push_back(read_f64());
            long fv = read_int();
            t.face_start.push_back((unsigned short)(t.face_points.size() / 3));
            unsigned long long mask = 0ull;
            for (long k = 0; k < fv; ++k) {
                long v = read_int();
                if (v < 0 || v >= nv) fail("face vertex index");
                for (int c = 0; c < 3; ++c) t.face_points.push_back(t.vertices[3 * v + c]);
                if (v < 64) mask |= 1ull << v;
            }
            if (nv <= 64) t.face_mask.push_back(mask);
        }
        t.face_start.push_back((unsigned short)(t.face_points.size() / 3));
        t.radius = read_f64();
    }
    auto body = [&](long ti, double s, pd::V3<double> p, pd::Quat<double> q) {
        if (ti < 0 || ti >= nt) fail("template index");
        pd::BodyRef b;
        b.tpl = templates[ti].view();
        b.scale = s;
        b.pos = p;
        b.rot = q;
        return b;
    };

    // The workspaces are tens of kilobytes: on the heap, zero-initialised, reused for every case
    // (as a kernel thread reuses its local workspace).
    auto ws64 = std::make_unique<pd::PairWorkspace<double>>();
    auto ws32 = std::make_unique<pd::PairWorkspace<float>>();

    read_word("pairs");
    long np = read_int();
    for (long i = 0; i < np; ++i) {
        long ta = read_int();
        double sa = read_f64();
        pd::V3<double> pa = read_v3();
        pd::Quat<double> qa = read_quat();
        long tb = read_int();
        double sb = read_f64();
        pd::V3<double> pb = read_v3();
        pd::Quat<double> qb = read_quat();
        pd::V3<double> axis = read_v3();
        double margin = read_f64();
        pd::BodyRef a = body(ta, sa, pa, qa), b = body(tb, sb, pb, qb);
        if (mixed) {
            poison(*ws32);
            poison(*ws64);
            pd::PairGeometry g;
            int st = pd::overlap_pair_mixed(*ws32, *ws64, a, b, &g);
            std::printf("M %ld %d %d", i, st, g.intersects);
            put3(g.separating_axis);
            put_overlap(g.overlap);
            std::printf("\n");
            continue;
        }
        std::printf("P %ld", i);
        run_pair(*ws64, a, b);
        run_pair(*ws32, a, b);
        std::printf(" %d\n", pd::axis_separates(a, b, axis, margin) ? 1 : 0);
    }

    read_word("facets");
    long nk = read_int();
    for (long i = 0; i < nk; ++i) {
        long t = read_int();
        double s = read_f64();
        pd::V3<double> p = read_v3();
        pd::Quat<double> q = read_quat();
        pd::V3<double> origin = read_v3();
        pd::V3<double> tri[3];
        for (int k = 0; k < 3; ++k) tri[k] = read_v3();
        pd::BodyRef r = body(t, s, p, q);
        if (mixed) continue;
        std::printf("F %ld", i);
        run_facet(ws64->overlap, ws64->a, r, origin, tri);
        run_facet(ws32->overlap, ws32->a, r, origin, tri);
        std::printf("\n");
    }
    std::fclose(in);
    return 0;
}
