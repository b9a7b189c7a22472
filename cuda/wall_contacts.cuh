// Stage 6 on the GPU, part of contact.cu (included at its end, after the pair kernels and the
// templates in constant memory it uses): the wall list (`wall_candidates`), the prism overlap
// of each listed particle–facet (`wall_facet_overlaps`) and the per-particle wall contacts
// (`wall_contacts`). The GPU twin of `Simulation::wall_stage` in src/pipeline/walls.rs and of
// contact/wall.rs. Not a compilation unit of its own (it is not in KERNEL_FILES).
#pragma once
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
        // Marked for wall_contacts, which flags the particle and wall (PD_CONTACT_FAILED).
        o.volume = -(double)status;
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
        unsigned int failed = 0u;
        for (; m < m_end && items[m].x == (unsigned int)slot; ++m) {
            const double* q = overlaps + 12 * (size_t)m;
            // A facet whose prism overlap failed (wall_facet_overlaps): the first, in facet
            // order, as the CPU's WallMesh::contact stops at it. A negative volume means only
            // that: a prism overlap's volume is never negative (overlap.cuh turns a volume at
            // or below zero into no overlap; sphere_facet's is positive or zero).
            if (q[0] < 0.0 && failed == 0u) {
                failed = PD_CONTACT_FAILED | ((unsigned int)(-q[0]) & 0xffu);
            }
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
        if (failed != 0u) {
            wall_contact[slot] = failed;
            continue;
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
        params.rolling_friction = pm.rolling_friction;
        params.damping = pm.damping;
        params.rocking = !PD_SPHERES;
        params.trajectory = PD_FACE_TRAJECTORY;
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
        kin.inverse_mass_a = 1.0 / p.mass[i];
        kin.inverse_mass_b = 0.0;
        kin.split_a = mass_share(p.contacts[i]);
        kin.split_b = 1.0;
        double area = norm(world.dv_dxb);
        if (area > 0.0) {
            V3<double> nrm = (-world.dv_dxb) / area;
            double inverse = 0.0, split = 0.0;
            double term = inverse_mass_term(p.mass[i], ip, qp, xp, c, nrm);
            inverse += term;
            split += kin.split_a * term;
            kin.effective_mass = 1.0 / inverse;
            kin.dashpot_mass = 1.0 / split;
        } else {
            kin.effective_mass = p.mass[i];
            kin.dashpot_mass = p.mass[i] / kin.split_a;
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
