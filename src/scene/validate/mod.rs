//! From TOML text to a resolved [`Scene`]: syntax, schema (serde), then every value checked
//! with its full dotted key. Checking goes on after a problem so one run lists them all.
//!
//! This file holds the entry point, the file-wide checks and the [`Validator`] helpers; each
//! group of sections is checked in its own file.

mod assemble;
mod insertions;
mod materials;
mod simulation;

use super::insertion::{DEFAULT_MAX_ATTEMPTS, Insertion, InsertionMode, TiledPacking};
use super::schema::{self, SceneFile, SpanIndex, Vec3};
use super::walls::Wall;
use super::*;
use crate::io::Packing;
use crate::shape::{ConvexTemplate, rounded};
use nalgebra::Unit;
use std::collections::HashMap;

/// Default gravity (m/s²): standard gravity along −z.
pub const DEFAULT_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];
/// Default per-particle output fields.
pub const DEFAULT_FIELDS: [&str; 5] = ["id", "type", "velocity", "angular_velocity", "rank"];
/// Default steps between progress log lines.
pub const DEFAULT_LOG_INTERVAL: u64 = 1000;

/// The finest position difference contacts need, as a fraction of the smallest particle
/// radius: overlaps of 1e-6 R are typical at rest under gravity, so the f64 spacing of every
/// coordinate of the domain must be at most this.
pub const POSITION_RESOLUTION: f64 = 1e-6;

/// The most a wall's fastest point may move in one step, as a fraction of the smallest
/// particle's volume-equivalent radius: a wall that jumps further passes through contacts in a
/// few steps, which no contact law resolves.
pub const MAX_WALL_STEP_FRACTION: f64 = 0.1;

/// Host memory a particle takes at the least (bytes): its state in [`crate::state::Particles`]
/// (id, kind, scale, mass, position, velocity, angular velocity, force, torque, inertia,
/// orientation) plus its bounding radius and the neighbour list's reference position. The run
/// needs more (pair list, contact history, output copies): this bound only refuses what
/// certainly cannot run.
pub const HOST_BYTES_PER_PARTICLE: u64 = {
    use std::mem::size_of;
    (size_of::<u64>()
        + size_of::<u32>()
        + 3 * size_of::<f64>()
        + 7 * size_of::<Vector3<f64>>()
        + size_of::<nalgebra::UnitQuaternion<f64>>()) as u64
};

/// Physical memory of this machine in bytes (`MemTotal` of `/proc/meminfo`); `None` where it
/// cannot be read, and then no memory bound is applied.
pub fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

pub(super) fn build(text: &str, base: &Path, file_name: &str) -> Result<Scene, SceneError> {
    let index = match toml::de::DeTable::parse(text) {
        Ok(doc) => SpanIndex::new(text, doc.get_ref()),
        Err(e) => {
            let empty = SpanIndex::new(text, &Default::default());
            let (line, column) = empty.line_col(text, e.span().map_or(0, |s| s.start));
            return Err(SceneError::Syntax {
                file: file_name.to_string(),
                line,
                column,
                message: e.message().to_string(),
            });
        }
    };
    // Schema errors (unknown keys, wrong types) are collected one at a time: each offending
    // key is blanked out of the text (spaces, so every span and line stays where it was) and
    // the text is read again, so that all of them are listed together and the value checks
    // still run on what remains. A required key of the wrong type, once blanked, is missing:
    // a placeholder of a type the schema takes is written where it was, so that reading goes
    // on (the placeholder's own value errors are not reported). A required key missing from
    // the file stops reading there with what was found.
    let mut errors: Vec<KeyError> = Vec::new();
    let mut current = text.to_string();
    // Paths blanked for their type (by key), and the keys standing on a placeholder.
    let mut blanked_at: Vec<(String, String)> = Vec::new();
    let mut placeholders: Vec<String> = Vec::new();
    let raw: SceneFile = loop {
        let e = match toml::from_str::<SceneFile>(&current) {
            Ok(raw) => break raw,
            Err(e) => e,
        };
        let span = e.span().unwrap_or(0..0);
        let path = index.path_at(&span);
        let (key, message) = schema::explain_serde_message(&path, e.message());
        // A missing section is nowhere in the file: no line to point at.
        let line = if schema::ROOT_REQUIRED.contains(&key.as_str()) {
            None
        } else {
            e.span().map(|s| index.line_col(text, s.start).0)
        };
        let missing = e.message().starts_with("missing field ");
        // A key blanked for its type is then missing: it was reported already.
        if missing && let Some((_, at)) = blanked_at.iter().find(|(k, _)| *k == key) {
            match placeholder(&current, text, &index, at, &key) {
                Some(t) if !placeholders.contains(&key) => {
                    placeholders.push(key);
                    current = t;
                    continue;
                }
                _ => {
                    return Err(SceneError::Invalid {
                        file: file_name.to_string(),
                        errors,
                    });
                }
            }
        }
        let blanked = (!missing && errors.len() < 100)
            .then(|| blank_key(&current, &index, &path))
            .flatten();
        if blanked.is_some() {
            blanked_at.push((key.clone(), path.clone()));
        }
        errors.push(KeyError { key, line, message });
        match blanked {
            Some(t) if toml::de::DeTable::parse(&t).is_ok() => current = t,
            _ => {
                return Err(SceneError::Invalid {
                    file: file_name.to_string(),
                    errors,
                });
            }
        }
    };
    errors.sort_by_key(|e| e.line);
    let schema_errors = errors.len();
    let mut v = Validator {
        base,
        index: &index,
        errors,
    };
    let scene = v.scene(raw, file_name);
    // A placeholder's own value errors say nothing about the file, nor does a blanked key's
    // absence (its type error is listed).
    let on_placeholder = |key: &str| {
        blanked_at.iter().map(|(k, _)| k).any(|p| {
            key == p
                || key
                    .strip_prefix(p.as_str())
                    .is_some_and(|r| r.starts_with(['.', '[']))
        })
    };
    let mut k = 0;
    v.errors.retain(|e| {
        k += 1;
        k <= schema_errors || !on_placeholder(&e.key)
    });
    if v.errors.is_empty() {
        Ok(scene)
    } else {
        Err(SceneError::Invalid {
            file: file_name.to_string(),
            errors: v.errors,
        })
    }
}

/// `current` with a placeholder value written where the key at `path` of the original `text`
/// was (blanked for its type, and required): the first of `0`, `""`, `false`, `[]`, `{}` with
/// which the file reads past that key, written as `name=value` into the key's blanked span,
/// padded with spaces (so no span or line moves). `None` when none fits or none is taken.
fn placeholder(
    current: &str,
    text: &str,
    index: &SpanIndex,
    path: &str,
    key: &str,
) -> Option<String> {
    let (name, value) = index.spans_of(path)?;
    let span = name.start.min(value.start)..name.end.max(value.end);
    if text[span.clone()].contains('\n') {
        return None;
    }
    let key_text = &text[name];
    ["0", "\"\"", "false", "[]", "{}"]
        .iter()
        .find_map(|candidate| {
            let written = format!("{key_text}={candidate}");
            if written.len() > span.len() || written.contains('\n') {
                return None;
            }
            let mut t = current.to_string();
            let padded = format!("{written:<width$}", width = span.len());
            t.replace_range(span.clone(), &padded);
            // Still refused there: the error falls on the placeholder, or names the key.
            let still = match toml::from_str::<SceneFile>(&t) {
                Ok(_) => false,
                Err(e) => {
                    let at = e.span().unwrap_or(0..0);
                    (at.start < span.end && span.start < at.end.max(at.start + 1))
                        || schema::explain_serde_message(&index.path_at(&at), e.message()).0 == key
                }
            };
            (!still && toml::de::DeTable::parse(&t).is_ok()).then_some(t)
        })
}

/// `text` with the key at `path` and its value replaced by spaces (newlines kept, so spans and
/// lines do not move), with the comma that separated it in an inline table or array, and with
/// its whole `[header]` line when it is a table header. `None` when `path` is not in the file.
fn blank_key(text: &str, index: &SpanIndex, path: &str) -> Option<String> {
    let (key, value) = index.spans_of(path)?;
    let bytes = text.as_bytes();
    let (mut start, mut end) = (key.start.min(value.start), key.end.max(value.end));
    let line_start = text[..key.start].rfind('\n').map_or(0, |i| i + 1);
    // A key whose line starts with `[` is a table header (an array element's path ends in `]`).
    if !path.ends_with(']') && text[line_start..].trim_start().starts_with('[') {
        // A table header: its keys follow it up to the next header, and would otherwise be
        // read as keys of the table before it.
        start = line_start;
        let mut pos = text[start..].find('\n').map_or(text.len(), |i| start + i);
        while pos < text.len() {
            let next = pos + 1;
            if text[next..].trim_start().starts_with('[') {
                break;
            }
            pos = text[next..].find('\n').map_or(text.len(), |i| next + i);
        }
        end = end.max(pos);
    } else {
        let mut after = end;
        while after < bytes.len() && (bytes[after] == b' ' || bytes[after] == b'\t') {
            after += 1;
        }
        if bytes.get(after) == Some(&b',') {
            end = after + 1;
        } else {
            let mut before = start;
            while before > 0 && (bytes[before - 1] == b' ' || bytes[before - 1] == b'\t') {
                before -= 1;
            }
            if before > 0 && bytes[before - 1] == b',' {
                start = before - 1;
            }
        }
    }
    if start >= end
        || end > text.len()
        || !text.is_char_boundary(start)
        || !text.is_char_boundary(end)
    {
        return None;
    }
    let blank: String = text[start..end]
        .chars()
        .map(|c| match c {
            '\n' => "\n".to_string(),
            // As many spaces as the character has bytes: offsets must not move.
            c => " ".repeat(c.len_utf8()),
        })
        .collect();
    Some(format!("{}{blank}{}", &text[..start], &text[end..]))
}

/// Collects key errors while turning the raw sections into resolved ones; section-specific
/// checks live beside their types (walls.rs, insertion.rs; schema/values.rs for values of
/// mixed type).
pub(super) struct Validator<'a> {
    base: &'a Path,
    index: &'a SpanIndex,
    errors: Vec<KeyError>,
}

/// `"a", "b"` or `none`, for messages listing defined names.
pub(super) fn names<'a>(it: impl Iterator<Item = &'a String>) -> String {
    let v: Vec<String> = it.map(|s| format!("\"{s}\"")).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

impl Validator<'_> {
    pub(super) fn err(&mut self, key: &str, message: impl Into<String>) {
        self.errors.push(KeyError {
            key: key.to_string(),
            line: self.index.line_of(key),
            message: message.into(),
        });
    }

    pub(super) fn positive(&mut self, key: &str, x: f64) -> f64 {
        if !(x > 0.0 && x.is_finite()) {
            self.err(key, format!("must be a positive finite number, got {x}"));
        }
        x
    }

    pub(super) fn non_negative(&mut self, key: &str, x: f64) -> f64 {
        if !(x >= 0.0 && x.is_finite()) {
            self.err(key, format!("must be a finite number ≥ 0, got {x}"));
        }
        x
    }

    pub(super) fn vector(&mut self, key: &str, v: Vec3) -> Vector3<f64> {
        if v.iter().any(|x| !x.is_finite()) {
            self.err(key, format!("components must be finite, got {v:?}"));
        }
        Vector3::from(v)
    }

    pub(super) fn direction(&mut self, key: &str, v: Vec3) -> Unit<Vector3<f64>> {
        let w = self.vector(key, v);
        Unit::try_new(w, 1e-300).unwrap_or_else(|| {
            self.err(key, "must be a non-zero vector");
            Vector3::z_axis()
        })
    }

    pub(super) fn resolve(&self, path: &str) -> PathBuf {
        self.base.join(path)
    }

    /// Errors for each present parameter that `kind` does not take.
    pub(super) fn only(
        &mut self,
        prefix: &str,
        kind: &str,
        present: &[(&str, bool)],
        allowed: &[&str],
    ) {
        for (name, is_set) in present {
            if *is_set && !allowed.contains(name) {
                let list = if allowed.is_empty() {
                    "none".into()
                } else {
                    allowed.join(", ")
                };
                self.err(
                    &format!("{prefix}.{name}"),
                    format!("not allowed for kind = \"{kind}\"; allowed: {list}"),
                );
            }
        }
    }

    pub(super) fn required<T: Copy>(
        &mut self,
        key: &str,
        kind: &str,
        x: Option<T>,
        fallback: T,
    ) -> T {
        x.unwrap_or_else(|| {
            self.err(key, format!("required for kind = \"{kind}\""));
            fallback
        })
    }
}
