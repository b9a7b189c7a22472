//! Values that may be one of several TOML types (a particle's scale, an insertion's
//! orientation), checked from `toml::Value` because serde structs cannot give them good errors.

use super::{AxisAngleSection, explain_serde_message};
use crate::scene::{OrientationMode, ScaleDistribution};
use nalgebra::UnitQuaternion;

/// Values that are one of several TOML types (a number or a table, a string or a table), which
/// serde structs cannot express with good errors: parsed here from `toml::Value`.
impl crate::scene::validate::Validator<'_> {
    // Scene-wide, not schema-only: validate/materials.rs and validate/insertions.rs call these.
    pub(in crate::scene) fn scale(
        &mut self,
        key: &str,
        v: Option<&toml::Value>,
    ) -> ScaleDistribution {
        let number = |v: &toml::Value| match v {
            toml::Value::Float(x) => Some(*x),
            toml::Value::Integer(i) => Some(*i as f64),
            _ => None,
        };
        let Some(v) = v else {
            return ScaleDistribution::Fixed(1.0);
        };
        if let Some(x) = number(v) {
            return ScaleDistribution::Fixed(self.positive(key, x));
        }
        let Some(t) = v.as_table() else {
            self.err(key, "must be a number or a table { distribution = \"uniform\" | \"normal\" | \"fixed\", ... }");
            return ScaleDistribution::Fixed(1.0);
        };
        let dist = t.get("distribution").and_then(|d| d.as_str()).unwrap_or("");
        let allowed: &[&str] = match dist {
            "fixed" => &["distribution", "value"],
            "uniform" => &["distribution", "min", "max"],
            "normal" => &["distribution", "mean", "std", "min", "max"],
            _ => {
                self.err(
                    &format!("{key}.distribution"),
                    "required; allowed: \"fixed\", \"uniform\", \"normal\"",
                );
                return ScaleDistribution::Fixed(1.0);
            }
        };
        let get = |s: &mut Self, name: &str| -> f64 {
            let sub = format!("{key}.{name}");
            match t.get(name).map(number) {
                Some(Some(x)) => s.positive(&sub, x),
                Some(None) => {
                    s.err(&sub, "must be a number");
                    1.0
                }
                None => {
                    s.err(&sub, format!("required for distribution = \"{dist}\""));
                    1.0
                }
            }
        };
        for name in t.keys() {
            if !allowed.contains(&name.as_str()) {
                self.err(
                    &format!("{key}.{name}"),
                    format!(
                        "unknown key for distribution = \"{dist}\"; allowed keys: {}",
                        allowed.join(", ")
                    ),
                );
            }
        }
        match dist {
            "fixed" => ScaleDistribution::Fixed(get(self, "value")),
            "uniform" => {
                let (min, max) = (get(self, "min"), get(self, "max"));
                if min >= max {
                    self.err(
                        &format!("{key}.max"),
                        format!("must exceed min ({min}), got {max}"),
                    );
                }
                ScaleDistribution::Uniform { min, max }
            }
            _ => {
                let (mean, std, min, max) = (
                    get(self, "mean"),
                    get(self, "std"),
                    get(self, "min"),
                    get(self, "max"),
                );
                if !(min <= mean && mean <= max && min < max) {
                    self.err(key, format!("need min < max and min ≤ mean ≤ max, got min {min}, mean {mean}, max {max}"));
                }
                ScaleDistribution::Normal {
                    mean,
                    std,
                    min,
                    max,
                }
            }
        }
    }

    pub(in crate::scene) fn orientation(
        &mut self,
        key: &str,
        v: Option<&toml::Value>,
    ) -> OrientationMode {
        let allowed = "allowed: \"random\", \"identity\", or { axis = [x, y, z], angle = degrees }";
        match v {
            None => OrientationMode::Random,
            Some(toml::Value::String(s)) if s == "random" => OrientationMode::Random,
            Some(toml::Value::String(s)) if s == "identity" => {
                OrientationMode::Fixed(UnitQuaternion::identity())
            }
            Some(toml::Value::Table(t)) => {
                let r: Result<AxisAngleSection, _> = toml::Value::Table(t.clone()).try_into();
                match r {
                    Ok(aa) => {
                        let axis = self.direction(&format!("{key}.axis"), aa.axis);
                        if !aa.angle.is_finite() {
                            self.err(&format!("{key}.angle"), "must be a finite angle in degrees");
                        }
                        OrientationMode::Fixed(UnitQuaternion::from_axis_angle(
                            &axis,
                            aa.angle.to_radians(),
                        ))
                    }
                    Err(e) => {
                        let (k, m) = explain_serde_message(key, e.message());
                        self.err(&k, m);
                        OrientationMode::Random
                    }
                }
            }
            Some(other) => {
                self.err(key, format!("got {other}; {allowed}"));
                OrientationMode::Random
            }
        }
    }
}
