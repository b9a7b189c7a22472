//! `[[insertion]]` sections, and the memory the particles inserted at the start will need.

use super::*;

impl Validator<'_> {
    pub(super) fn insertions(
        &mut self,
        list: &[schema::InsertionSection],
        scene: &Scene,
    ) -> Vec<Insertion> {
        let mut out = Vec::new();
        for (i, s) in list.iter().enumerate() {
            let k = |f: &str| format!("insertions[{i}].{f}");
            let particle_type = scene
                .particle_type_index(&s.particle_type)
                .unwrap_or_else(|| {
                    let defined = names(scene.particle_types.iter().map(|p| &p.name));
                    self.err(
                        &k("type"),
                        format!(
                            "unknown particle type \"{}\"; defined: {defined}",
                            s.particle_type
                        ),
                    );
                    usize::MAX
                });
            let region = self.region(&k("region"), &s.region, scene, particle_type);
            let mode = self.insertion_mode(i, s);
            let orientation = self.orientation(&k("orientation"), s.orientation.as_ref());
            let velocity = self.vector(&k("velocity"), s.velocity.unwrap_or_default());
            let angular_velocity = self.vector(
                &k("angular_velocity"),
                s.angular_velocity.unwrap_or_default(),
            );
            let max_attempts = s.max_attempts.unwrap_or(DEFAULT_MAX_ATTEMPTS);
            if max_attempts == 0 {
                self.err(&k("max_attempts"), "must be at least 1");
            }
            let lattice = s.lattice.map(|l| self.lattice(i, l, &region, &mode));
            let packing = s
                .packing
                .as_deref()
                .and_then(|file| self.packing(i, file, s, &region, &mode, scene, particle_type));
            let state = s
                .state
                .as_deref()
                .and_then(|file| self.state(i, file, s, &region, &mode, scene, particle_type));
            out.push(Insertion {
                particle_type,
                region,
                mode,
                orientation,
                velocity,
                angular_velocity,
                max_attempts,
                lattice,
                packing,
                state,
            });
        }
        self.start_memory(&out);
        out
    }

    /// `insertions[i].count` or `.rate` with the keys that go with it: the insertion's mode.
    fn insertion_mode(&mut self, i: usize, s: &schema::InsertionSection) -> InsertionMode {
        let k = |f: &str| format!("insertions[{i}].{f}");
        let rate_only = [
            ("start", s.start.is_some()),
            ("end", s.end.is_some()),
            ("total", s.total.is_some()),
            ("interval", s.interval.is_some()),
        ];
        match (s.count, s.rate) {
            (Some(n), None) => {
                if n == 0 {
                    self.err(&k("count"), "must be at least 1");
                }
                for (name, set) in rate_only {
                    if set {
                        self.err(
                            &k(name),
                            "only allowed with rate (a count insertion places all at the start)",
                        );
                    }
                }
                InsertionMode::Count(n)
            }
            (None, Some(r)) => {
                let per_second = self.positive(&k("rate"), r);
                let start = self.non_negative(&k("start"), s.start.unwrap_or(0.0));
                if let Some(e) = s.end.filter(|e| !(*e > start && e.is_finite())) {
                    self.err(
                        &k("end"),
                        format!("must be finite and after start ({start}), got {e}"),
                    );
                }
                if s.total == Some(0) {
                    self.err(&k("total"), "must be at least 1");
                }
                InsertionMode::Rate {
                    per_second,
                    start,
                    end: s.end,
                    total: s.total,
                    interval: s.interval.map(|x| self.positive(&k("interval"), x)),
                }
            }
            _ => {
                self.err(
                    &k("count"),
                    "give exactly one of count (all at the start) or rate (per second)",
                );
                InsertionMode::Count(0)
            }
        }
    }

    /// `insertions[i].lattice`: the spacings, checked against the mode and, for a count, the
    /// sites the region holds.
    fn lattice(
        &mut self,
        i: usize,
        l: Vec3,
        region: &Region,
        mode: &InsertionMode,
    ) -> Vector3<f64> {
        let k = |f: &str| format!("insertions[{i}].{f}");
        let v = self.vector(&k("lattice"), l);
        if !(v.iter().all(|&x| x > 0.0 && x.is_finite())) {
            self.err(
                &k("lattice"),
                format!("spacings must be positive, got {v:?}"),
            );
        }
        if !matches!(mode, InsertionMode::Count(_)) {
            self.err(
                &k("lattice"),
                "only allowed with count (a lattice is filled at the start)",
            );
        }
        match (region, mode) {
            (Region::Box { min, max }, InsertionMode::Count(n)) => {
                let points: f64 = (0..3)
                    .map(|a| ((max[a] - min[a]) / v[a] + 1e-9).floor().max(0.0))
                    .product();
                if (*n as f64) > points {
                    self.err(
                        &k("count"),
                        format!("{n} particles do not fit on the lattice: it has {points} points in the region"),
                    );
                }
            }
            (
                Region::Cylinder {
                    base,
                    axis,
                    radius,
                    height,
                },
                InsertionMode::Count(n),
            ) if v.iter().all(|&x| x > 0.0 && x.is_finite()) => {
                // Bounded before it is counted: the sites are enumerated.
                let cells = (2.0 * radius / v.x) * (2.0 * radius / v.y) * (height / v.z);
                if cells > 1e9 {
                    self.err(
                        &k("lattice"),
                        format!("{cells:.3e} lattice points around the cylinder: at most 1e9"),
                    );
                } else {
                    let sites =
                        crate::scene::insertion::cylinder_sites(base, axis, *radius, *height, &v)
                            .len();
                    if *n as usize > sites {
                        self.err(
                            &k("count"),
                            format!("{n} particles do not fit on the lattice: it has {sites} points in the cylinder"),
                        );
                    }
                }
            }
            _ => {}
        }
        v
    }

    /// `insertions[i].packing`: the file read and checked, and the box region measured in
    /// whole cells; `None` (with errors recorded) when anything does not fit.
    #[allow(clippy::too_many_arguments)]
    fn packing(
        &mut self,
        i: usize,
        file: &str,
        s: &schema::InsertionSection,
        region: &Region,
        mode: &InsertionMode,
        scene: &Scene,
        particle_type: usize,
    ) -> Option<TiledPacking> {
        let k = |f: &str| format!("insertions[{i}].{f}");
        for (name, set) in [
            ("lattice", s.lattice.is_some()),
            ("orientation", s.orientation.is_some()),
        ] {
            if set {
                self.err(
                    &k(name),
                    "not allowed with packing (the packing gives every position and orientation)",
                );
            }
        }
        let path = self.resolve(file);
        let packing = match Packing::read(&path) {
            Ok(p) => p,
            Err(e) => {
                self.err(&k("packing"), e.to_string());
                return None;
            }
        };
        if let Region::Cylinder {
            base,
            axis,
            radius,
            height,
        } = region
        {
            // Tiles over the square prism around the cylinder, in its frame; the particles whose
            // bounding sphere lies inside are kept, and must hold the count.
            let c = packing.cell;
            let n = [2.0 * radius / c[0], 2.0 * radius / c[1], height / c[2]];
            let total =
                n.iter().map(|x| x.ceil()).product::<f64>() * packing.particles.len() as f64;
            if total > 1e9 {
                self.err(
                    &k("region"),
                    format!("{total:.3e} packing particles around the cylinder: at most 1e9"),
                );
                return None;
            }
            let tiled = TiledPacking {
                file: path,
                packing: std::sync::Arc::new(packing),
                tiles: n.map(|x| x.ceil() as u64),
            };
            let bound = scene
                .particle_types
                .get(particle_type)
                .and_then(|t| scene.templates.get(t.template))
                .map_or(0.0, |t| t.circumscribed_radius);
            let kept = tiled.in_cylinder(base, axis, *radius, *height, bound).len() as u64;
            match mode {
                InsertionMode::Count(n) if *n <= kept => {}
                InsertionMode::Count(n) => self.err(
                    &k("count"),
                    format!("{n} particles do not fit: the packing tiled over the cylinder has {kept} whose bounding sphere lies inside it"),
                ),
                _ => self.err(
                    &k("packing"),
                    "only allowed with count (a packing is placed at the start)",
                ),
            }
            self.packing_scales(i, s, &tiled, scene, particle_type);
            return Some(tiled);
        }
        let Region::Box { min, max } = region else {
            unreachable!("regions are boxes or cylinders")
        };
        let mut tiles = [0u64; 3];
        for a in 0..3 {
            let size = max[a] - min[a];
            let n = (size / packing.cell[a]).round();
            if n < 1.0 || (n * packing.cell[a] - size).abs() > 1e-9 * size {
                self.err(
                    &k("region"),
                    format!(
                        "the box must be a whole number of the packing's cells ({:e} m along {}); its size there is {size:e} m = {:.6} cells",
                        packing.cell[a],
                        ["x", "y", "z"][a],
                        size / packing.cell[a]
                    ),
                );
                return None;
            }
            tiles[a] = n as u64;
        }
        let tiled = TiledPacking {
            file: path,
            packing: std::sync::Arc::new(packing),
            tiles,
        };
        match mode {
            InsertionMode::Count(n) if *n == tiled.count() => {}
            InsertionMode::Count(n) => self.err(
                &k("count"),
                format!(
                    "{n} does not match the packing: {} particles per cell × {}×{}×{} cells = {}",
                    tiled.packing.particles.len(),
                    tiles[0],
                    tiles[1],
                    tiles[2],
                    tiled.count()
                ),
            ),
            _ => self.err(
                &k("packing"),
                "only allowed with count (a packing is placed at the start)",
            ),
        }
        self.packing_scales(i, s, &tiled, scene, particle_type);
        Some(tiled)
    }

    /// `insertions[i].state`: the checkpoint read and checked, its particles inside the region
    /// taken, each with the insertion type's mass at its scale (the same template and
    /// material), and their number the count; `None` (with errors recorded) otherwise.
    #[allow(clippy::too_many_arguments)]
    fn state(
        &mut self,
        i: usize,
        file: &str,
        s: &schema::InsertionSection,
        region: &Region,
        mode: &InsertionMode,
        scene: &Scene,
        particle_type: usize,
    ) -> Option<ImportedState> {
        let k = |f: &str| format!("insertions[{i}].{f}");
        for (name, set) in [
            ("lattice", s.lattice.is_some()),
            ("packing", s.packing.is_some()),
            ("orientation", s.orientation.is_some()),
            ("velocity", s.velocity.is_some()),
            ("angular_velocity", s.angular_velocity.is_some()),
        ] {
            if set {
                self.err(
                    &k(name),
                    "not allowed with state (the checkpoint gives every position, orientation and velocity)",
                );
            }
        }
        let path = self.resolve(file);
        let c = match crate::io::read_checkpoint(&path) {
            Ok(c) => c,
            Err(e) => {
                self.err(&k("state"), e.to_string());
                return None;
            }
        };
        // An unknown type was reported where it was named.
        scene.particle_types.get(particle_type)?;
        let p = &c.particles;
        let mut bodies = Vec::new();
        for j in 0..p.len() {
            if !region.contains(&p.position[j]) {
                continue;
            }
            if let Some(why) = foreign_body(scene, particle_type, p, j) {
                let e = format!("{}: particle {j} (id {}) {why}", path.display(), p.id[j]);
                self.err(&k("state"), e);
                return None;
            }
            bodies.push(ImportedBody {
                position: p.position[j],
                orientation: p.orientation[j],
                velocity: p.velocity[j],
                angular_velocity: p.angular_velocity[j],
                scale: p.scale[j],
            });
        }
        match mode {
            InsertionMode::Count(n) if *n == bodies.len() as u64 => {}
            InsertionMode::Count(n) => self.err(
                &k("count"),
                format!(
                    "{n} does not match the state: {} of the {} particles of {} have their centre in the region",
                    bodies.len(),
                    p.len(),
                    path.display()
                ),
            ),
            _ => self.err(&k("state"), "only allowed with count (a state is placed at the start)"),
        }
        Some(ImportedState {
            file: path,
            bodies: std::sync::Arc::new(bodies),
        })
    }

    /// A packing's scales must all be the particle type's fixed scale.
    fn packing_scales(
        &mut self,
        i: usize,
        s: &schema::InsertionSection,
        tiled: &TiledPacking,
        scene: &Scene,
        particle_type: usize,
    ) {
        let k = |f: &str| format!("insertions[{i}].{f}");
        if let Some(dist) = scene.scale_distributions.get(particle_type) {
            let scales = tiled.packing.particles.iter().map(|p| p.scale);
            match dist {
                ScaleDistribution::Fixed(f) if scales.clone().all(|x| x == *f) => {}
                _ => {
                    let (lo, hi) =
                        scales.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
                    self.err(
                        &k("packing"),
                        format!(
                            "the packing's scales ({lo:e} … {hi:e}) must all equal the particle type \"{}\"'s fixed scale ({dist:?})",
                            s.particle_type
                        ),
                    );
                }
            }
        }
    }

    /// Refuses count insertions whose particles, all placed at the start, cannot fit in this
    /// machine's memory: they would otherwise be allocated one by one until the process is
    /// killed, long after `polydem check` said the scene was fine.
    pub(super) fn start_memory(&mut self, insertions: &[Insertion]) {
        let counts: Vec<(usize, u64)> = insertions
            .iter()
            .enumerate()
            .filter_map(|(k, ins)| match ins.mode {
                InsertionMode::Count(n) => Some((k, n)),
                _ => None,
            })
            .collect();
        let total: u128 = counts.iter().map(|&(_, n)| n as u128).sum();
        let Some(&(largest, _)) = counts.iter().max_by_key(|&&(_, n)| n) else {
            return;
        };
        let need = total * HOST_BYTES_PER_PARTICLE as u128;
        let Some(have) = physical_memory() else {
            return;
        };
        if need > have as u128 {
            let gib = |b: f64| b / (1u64 << 30) as f64;
            self.err(
                &format!("insertions[{largest}].count"),
                format!(
                    "{total} particles placed at the start need at least {:.1} GiB of memory \
                     ({HOST_BYTES_PER_PARTICLE} bytes each for the particle state alone), more \
                     than this machine's {:.1} GiB; lower count",
                    gib(need as f64),
                    gib(have as f64)
                ),
            );
        }
    }
}

/// Why particle `j` of a checkpoint cannot be a body of `particle_type` (its mass, or its
/// scale), or `None` when it can.
fn foreign_body(
    scene: &Scene,
    particle_type: usize,
    p: &crate::state::Particles,
    j: usize,
) -> Option<String> {
    let ptype = &scene.particle_types[particle_type];
    let name = &ptype.name;
    let density = scene
        .materials
        .get(ptype.material)
        .map_or(0.0, |m| m.density);
    let t = scene.templates.get(ptype.template)?;
    let (scale, mass) = (p.scale[j], density * t.volume * p.scale[j].powi(3));
    if (p.mass[j] - mass).abs() > 1e-12 * mass {
        let m = p.mass[j];
        return Some(format!(
            "has mass {m} at scale {scale}; particle type \"{name}\" has {mass} there (another shape or material)"
        ));
    }
    // The scene's cutoff, halo, wall grids and critical step are sized from the types' scale
    // ranges (`Scene::max_bounding_radius`, `min_equivalent_radius`): a body outside its type's
    // range would be larger or smaller than all of them assume.
    let dist = scene.scale_distributions.get(particle_type)?;
    let (lo, hi) = (dist.min_scale(), dist.max_scale());
    (!(lo..=hi).contains(&scale)).then(|| {
        format!(
            "has scale {scale:e}, outside particle type \"{name}\"'s scales {lo:e} … {hi:e} ({dist:?}); give the type a scale range that holds the state's"
        )
    })
}
