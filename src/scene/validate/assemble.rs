//! The whole scene from its raw sections, and the checks that need more than one section:
//! coordinates the domain can resolve, wall speeds against the time step.

use super::*;

impl Validator<'_> {
    pub(super) fn scene(&mut self, raw: SceneFile, file_name: &str) -> Scene {
        let mut simulation = self.simulation(&raw.simulation);
        let domain = self.domain(&raw.domain);
        let gravity = self.vector("gravity", raw.gravity.unwrap_or(DEFAULT_GRAVITY));
        let materials = self.materials(&raw.materials);
        let mat_index: HashMap<String, usize> = materials
            .iter()
            .enumerate()
            .map(|(i, m)| (m.name.clone(), i))
            .collect();
        let (templates, particle_types, scale_distributions) =
            self.particle_types(&raw.particle_types, &mat_index);
        let walls = self.walls(&raw.walls, &mat_index);
        let pairs = self.pairs(&raw.material_pairs, &mat_index, &particle_types, &walls);
        let raw_output = raw.output.unwrap_or_default();
        let output = self.output(&raw_output);
        let parallel = self.parallel(raw.parallel.as_ref());
        let mut scene = Scene {
            file: self.base.join(file_name),
            simulation: simulation.clone(),
            domain,
            gravity,
            materials,
            pairs,
            templates,
            particle_types,
            scale_distributions,
            insertions: Vec::new(),
            walls,
            output,
            parallel,
            key_lines: self.index.key_lines(),
        };
        scene.insertions = self.insertions(&raw.insertions, &scene);
        if !self.errors.is_empty() {
            return scene;
        }
        // Defaults that depend on the loaded templates and the resolved time step.
        if raw
            .simulation
            .neighbor
            .as_ref()
            .and_then(|n| n.skin)
            .is_none()
        {
            // 0.1 × the largest circumscribed diameter.
            simulation.neighbor.skin = 0.2 * scene.max_bounding_radius();
            scene.simulation = simulation;
        }
        let n = &mut scene.simulation.neighbor;
        if n.hybrid_skin.is_nan() {
            n.hybrid_skin = 2.0 * n.skin;
        } else if !(n.hybrid_skin >= n.skin && n.hybrid_skin.is_finite()) {
            let (h, s) = (n.hybrid_skin, n.skin);
            self.err(
                "simulation.neighbor.hybrid_skin",
                format!("must be finite and at least simulation.neighbor.skin ({s} m), got {h}"),
            );
        }
        self.domain_resolution(&scene);
        self.periodic_extent(&scene);
        let ts = critical_time_step(&scene);
        self.wall_speeds(&scene, ts.dt);
        if raw_output.series_interval.is_none() {
            scene.output.series_interval = scene.output.frame_interval.unwrap_or(100.0 * ts.dt);
        }
        if ts.fraction_of_rayleigh > 1.0 {
            tracing::warn!(
                "{file_name}: simulation.dt = {:.3e} s is {:.2} × the Rayleigh step {:.3e} s; \
                 the run is likely unstable",
                ts.dt,
                ts.fraction_of_rayleigh,
                ts.rayleigh
            );
        }
        scene
    }

    /// Refuses domains whose coordinates are too large for f64 to resolve the particles: the
    /// spacing of f64 near the largest coordinate must be at most [`POSITION_RESOLUTION`] of the
    /// smallest particle radius. Beyond it overlaps are rounding noise (false contacts at a
    /// half-width of 1e15 m; at ±1e308 the domain's width overflows and every contact is lost).
    pub(super) fn domain_resolution(&mut self, scene: &Scene) {
        let r_min = scene.min_equivalent_radius();
        if !r_min.is_finite() {
            return;
        }
        let d = &scene.domain;
        let largest = |v: &Vector3<f64>| v.iter().map(|x| x.abs()).fold(0.0, f64::max);
        let (key, c) = if largest(&d.max) >= largest(&d.min) {
            ("domain.max", largest(&d.max))
        } else {
            ("domain.min", largest(&d.min))
        };
        let need = POSITION_RESOLUTION * r_min;
        let spacing = c * f64::EPSILON;
        let width_finite = (d.max - d.min).iter().all(|w| w.is_finite());
        if spacing > need || !width_finite {
            self.err(
                key,
                format!(
                    "coordinates up to {c:.4e} m are resolved in f64 only to {spacing:.4e} m, \
                     but contacts of the smallest particles (radius {r_min:.4e} m) need positions \
                     to {POSITION_RESOLUTION:e} of it, {need:.4e} m; allowed: |coordinates| ≤ \
                     {:.4e} m (shift the domain towards the origin or shrink it)",
                    need / f64::EPSILON
                ),
            );
        }
    }

    /// Refuses a periodic axis shorter than [`Scene::least_periodic_extent`]: below it a
    /// particle can touch two images of another (or its own), and the minimum-image pair list
    /// holds one of them, so the other contact is lost. A periodic 2 × 2 × 2 lattice of
    /// compressed cubes, each pushed by its neighbour's image on one side only, flew apart.
    pub(super) fn periodic_extent(&mut self, scene: &Scene) {
        let least = scene.least_periodic_extent();
        if !least.is_finite() {
            return;
        }
        let d = &scene.domain;
        for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
            let width = d.max[k] - d.min[k];
            if d.periodic[k] && width < least {
                self.err(
                    "domain.max",
                    format!(
                        "the domain is periodic along {axis} over {width:.6e} m, less than twice \
                         the reach of a contact (2 × 2 r_max = {:.6e} m, r_max = {:.6e} m the \
                         largest circumscribed radius): a particle could touch two images of \
                         another and only one would be found; allowed: a periodic extent of at \
                         least {:.6e} m, or a non-periodic axis",
                        least,
                        0.25 * least,
                        least
                    ),
                );
            }
        }
    }

    /// Refuses walls whose fastest point moves more than [`MAX_WALL_STEP_FRACTION`] of the
    /// smallest particle's radius in one step: a contact with such a wall is not resolved at
    /// all (at `rpm = 1e300` particles simply vanished).
    pub(super) fn wall_speeds(&mut self, scene: &Scene, dt: f64) {
        let r_min = scene.min_equivalent_radius();
        if !(r_min.is_finite() && dt.is_finite()) {
            return;
        }
        let limit = MAX_WALL_STEP_FRACTION * r_min;
        for (i, w) in scene.walls.iter().enumerate() {
            let speed = w.motion.max_speed(&w.triangles);
            if speed * dt <= limit {
                continue;
            }
            let v_max = limit / dt;
            let (key, allowed) = match &w.motion {
                WallMotion::Rotate { rpm, .. } => (
                    "rpm",
                    format!("|rpm| ≤ {:.4e} at this step", rpm.abs() * v_max / speed),
                ),
                WallMotion::Sinusoidal { frequency, .. } => (
                    "frequency",
                    format!(
                        "2π × frequency × amplitude ≤ {v_max:.4e} m/s (frequency ≤ {:.4e} Hz at this amplitude)",
                        frequency * v_max / speed
                    ),
                ),
                _ => ("velocity", format!("|velocity| ≤ {v_max:.4e} m/s")),
            };
            self.err(
                &format!("walls[{i}].motion.{key}"),
                format!(
                    "wall \"{}\" moves too fast for the time step: its fastest point moves at \
                     {speed:.4e} m/s, {:.4e} m per step of dt = {dt:.4e} s, more than \
                     {MAX_WALL_STEP_FRACTION} × the smallest particle radius {r_min:.4e} m; \
                     allowed: {allowed} (or a smaller step)",
                    w.name,
                    speed * dt
                ),
            );
        }
    }
}
