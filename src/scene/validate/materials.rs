//! Materials, particle types (templates and scales) and the per-pair contact table, with the
//! material lookup that walls share.

use super::*;

impl Validator<'_> {
    pub(super) fn materials(&mut self, list: &[schema::MaterialSection]) -> Vec<Material> {
        if list.is_empty() {
            self.err("materials", "at least one [[materials]] entry is required");
        }
        let mut out: Vec<Material> = Vec::new();
        for (i, m) in list.iter().enumerate() {
            let k = |f: &str| format!("materials[{i}].{f}");
            if m.name.is_empty() {
                self.err(&k("name"), "must not be empty");
            } else if out.iter().any(|o| o.name == m.name) {
                self.err(
                    &k("name"),
                    format!("material \"{}\" is defined twice", m.name),
                );
            }
            self.positive(&k("youngs_modulus"), m.youngs_modulus);
            if !(m.poisson_ratio > -1.0 && m.poisson_ratio < 0.5) {
                self.err(
                    &k("poisson_ratio"),
                    format!(
                        "must be in the open interval (-1, 0.5), got {}",
                        m.poisson_ratio
                    ),
                );
            }
            self.positive(&k("density"), m.density);
            out.push(Material {
                name: m.name.clone(),
                youngs_modulus: m.youngs_modulus,
                poisson_ratio: m.poisson_ratio,
                density: m.density,
            });
        }
        out
    }

    // Scene-wide, not validate-only: walls.rs resolves each wall's material with it.
    pub(in crate::scene) fn material_ref(
        &mut self,
        key: &str,
        name: &str,
        mats: &HashMap<String, usize>,
    ) -> usize {
        mats.get(name).copied().unwrap_or_else(|| {
            let mut defined: Vec<&String> = mats.keys().collect();
            defined.sort_by_key(|n| mats[*n]);
            self.err(
                key,
                format!(
                    "unknown material \"{name}\"; defined: {}",
                    names(defined.into_iter())
                ),
            );
            0
        })
    }

    pub(super) fn particle_types(
        &mut self,
        list: &[schema::ParticleTypeSection],
        mats: &HashMap<String, usize>,
    ) -> (
        Vec<ConvexTemplate>,
        Vec<ParticleType>,
        Vec<ScaleDistribution>,
    ) {
        if list.is_empty() {
            self.err(
                "particle_types",
                "at least one [[particle_types]] entry is required",
            );
        }
        let (mut templates, mut types, mut scales) = (Vec::new(), Vec::new(), Vec::new());
        let mut sources: HashMap<String, usize> = HashMap::new();
        for (i, p) in list.iter().enumerate() {
            let k = |f: &str| format!("particle_types[{i}].{f}");
            if p.name.is_empty() {
                self.err(&k("name"), "must not be empty");
            } else if types.iter().any(|t: &ParticleType| t.name == p.name) {
                self.err(
                    &k("name"),
                    format!("particle type \"{}\" is defined twice", p.name),
                );
            }
            let material = self.material_ref(&k("material"), &p.material, mats);
            // A rounded template is another template: its own key, built from the sharp one.
            let rounding = p
                .rounding
                .map(|f| format!(" rounded {f:?}"))
                .unwrap_or_default();
            let round = |t: ConvexTemplate| match p.rounding {
                Some(f) => rounded(&t, f).map_err(|e| (k("rounding"), e)),
                None => Ok(t),
            };
            let (source, built) = match (&p.mesh, &p.generator) {
                (Some(m), None) => {
                    let path = self.resolve(m);
                    let key = format!("mesh:{}{rounding}", path.display());
                    let built = (!sources.contains_key(&key)).then(|| {
                        ConvexTemplate::from_file(&path)
                            .map_err(|e| (k("mesh"), e))
                            .and_then(round)
                    });
                    (key, built)
                }
                (None, Some(g)) => {
                    let key = format!("generator:{g:?}{rounding}");
                    let built = (!sources.contains_key(&key))
                        .then(|| g.build().map_err(|e| (k("generator"), e)).and_then(round));
                    (key, built)
                }
                _ => {
                    self.err(
                        &k("mesh"),
                        "give exactly one of mesh (a file) or generator (a table)",
                    );
                    (String::new(), None)
                }
            };
            let template = match built {
                Some(Ok(t)) => {
                    templates.push(t);
                    sources.insert(source, templates.len() - 1);
                    templates.len() - 1
                }
                Some(Err((key, e))) => {
                    self.err(&key, e.to_string());
                    0
                }
                None => sources.get(&source).copied().unwrap_or(0),
            };
            types.push(ParticleType {
                name: p.name.clone(),
                template,
                material,
            });
            scales.push(self.scale(&k("scale"), p.scale.as_ref()));
        }
        // The sphere fast path replaces the polyhedral stages for the whole scene (docs/design.md §1);
        // a sphere–polyhedron contact has no formula.
        let is_sphere = |t: &ParticleType| templates.get(t.template).is_some_and(|t| t.sphere);
        if let (Some(s), Some(q)) = (
            types.iter().position(is_sphere),
            types.iter().position(|t| !is_sphere(t)),
        ) {
            self.err(
                &format!("particle_types[{s}].generator"),
                format!(
                    "spheres (\"{}\") and polyhedra (\"{}\") cannot be mixed in one scene: \
                     sphere–polyhedron contacts are not supported; use only spheres, or a \
                     faceted polyhedron (e.g. kind = \"icosahedron\") in their place",
                    types[s].name, types[q].name
                ),
            );
        }
        (templates, types, scales)
    }

    pub(super) fn pairs(
        &mut self,
        list: &[schema::PairSection],
        mats: &HashMap<String, usize>,
        types: &[ParticleType],
        walls: &[Wall],
    ) -> PairTable {
        let mut table = PairTable::new(mats.len());
        for (i, p) in list.iter().enumerate() {
            let k = |f: &str| format!("material_pairs[{i}].{f}");
            let a = self.material_ref(&k("materials"), &p.materials[0], mats);
            let b = self.material_ref(&k("materials"), &p.materials[1], mats);
            if !(p.restitution > 0.0 && p.restitution <= 1.0) {
                self.err(
                    &k("restitution"),
                    format!("must be in (0, 1], got {}", p.restitution),
                );
            }
            self.non_negative(&k("friction"), p.friction);
            if let Some(r) = p.rolling_friction {
                self.non_negative(&k("rolling_friction"), r);
            }
            if mats.contains_key(&p.materials[0]) && mats.contains_key(&p.materials[1]) {
                if table.try_get(a, b).is_some() {
                    self.err(
                        &k("materials"),
                        format!("pair {:?} is given twice", p.materials),
                    );
                }
                table.set(
                    a,
                    b,
                    PairParameters {
                        restitution: p.restitution,
                        friction: p.friction,
                        rolling_friction: p.rolling_friction.unwrap_or(0.0),
                    },
                );
            }
        }
        if !self.errors.is_empty() {
            return table; // unknown names would make the missing list misleading
        }
        let name_of: HashMap<usize, &String> = mats.iter().map(|(n, i)| (*i, n)).collect();
        let mut particle_mats: Vec<usize> = types.iter().map(|t| t.material).collect();
        particle_mats.sort_unstable();
        particle_mats.dedup();
        let mut wall_mats: Vec<usize> = walls.iter().map(|w| w.material).collect();
        wall_mats.sort_unstable();
        wall_mats.dedup();
        let mut missing = Vec::new();
        for (n, &a) in particle_mats.iter().enumerate() {
            let partners = particle_mats[n..].iter().map(|&b| (b, "particles")).chain(
                wall_mats
                    .iter()
                    .filter(|w| !particle_mats[..n].contains(w))
                    .map(|&b| (b, "walls")),
            );
            for (b, with) in partners {
                if table.try_get(a, b).is_none()
                    && !missing.iter().any(|(x, y, _)| (*x, *y) == (a, b))
                {
                    missing.push((a, b, with));
                }
            }
        }
        if !missing.is_empty() {
            let list: Vec<String> = missing
                .iter()
                .map(|(a, b, with)| {
                    format!(
                        "[\"{}\", \"{}\"] (particles meet {with})",
                        name_of[a], name_of[b]
                    )
                })
                .collect();
            self.err(
                "material_pairs",
                format!(
                    "missing material pair(s): {}; add a [[material_pairs]] entry with materials, restitution and friction for each",
                    list.join(", ")
                ),
            );
        }
        table
    }
}
