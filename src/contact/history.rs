//! Contact history: the per-contact state that outlives a step (the tangential spring, the
//! approach speed of the current loading cycle, the twist angle), keyed by the pair of global
//! ids so that it survives neighbour-list rebuilds, reordering and migration (docs/design.md
//! §3).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Bit set in [`ContactKey::b`] when the second member is a wall (the rest is the wall index).
pub const WALL_BIT: u64 = 1 << 63;

/// A contact's identity: particle global ids `a < b`, or a particle `a` and a wall
/// `b = WALL_BIT | wall index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct ContactKey {
    pub a: u64,
    pub b: u64,
}

impl ContactKey {
    /// The key of a particle pair, lower id first (docs/design.md §4).
    pub fn particles(i: u64, j: u64) -> Self {
        ContactKey {
            a: i.min(j),
            b: i.max(j),
        }
    }

    /// The key of a particle–wall contact.
    pub fn wall(particle: u64, wall: usize) -> Self {
        ContactKey {
            a: particle,
            b: WALL_BIT | wall as u64,
        }
    }

    /// The wall index, when the contact is with a wall.
    pub fn wall_index(&self) -> Option<usize> {
        (self.b & WALL_BIT != 0).then_some((self.b & !WALL_BIT) as usize)
    }
}

/// State carried by one contact from step to step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ContactState {
    /// Tangential spring, kept in the current tangent plane, as `√k_t ξ` (ξ the stretch,
    /// √(N·m)): its energy `|s|²/2` does not change with the contact's stiffness
    /// ([`crate::contact::friction::stretch`]).
    pub spring: Vector3<f64>,
    /// Normal approach speed of the contact's current loading cycle, the Hunt–Crossley
    /// damping's reference speed, signed by the cycle's phase: positive while loading, negative
    /// while unloading ([`crate::contact::law::loading_cycle_speed`], docs/contact.md §2); 0
    /// marks a contact that has not been evaluated yet.
    #[serde(default)]
    pub approach_speed: f64,
    /// The torsional spring of twisting friction as `√k_tw φ` (φ the twist angle it holds,
    /// √(N·m)), carried at constant energy like the tangential spring.
    #[serde(default)]
    pub twist: f64,
}

/// All live contacts, sorted by key: lookups are binary searches and iteration order is
/// deterministic (checkpoints are byte-identical for identical states).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ContactHistory {
    entries: Vec<(ContactKey, ContactState)>,
}

impl ContactHistory {
    /// History from entries in any order (duplicates keep the last).
    pub fn from_entries(mut entries: Vec<(ContactKey, ContactState)>) -> Self {
        entries.sort_by_key(|e| e.0);
        entries.dedup_by(|later, earlier| {
            if later.0 == earlier.0 {
                *earlier = *later;
                true
            } else {
                false
            }
        });
        ContactHistory { entries }
    }

    /// Adds `more` (in any order; a few beside the history, say the entries migrating
    /// particles bring): the same history as [`ContactHistory::from_entries`] of this one's
    /// entries followed by `more` (a key held by both keeps `more`'s state), by one merge of
    /// the sorted `more` into the entries instead of sorting them all again.
    pub fn merge(&mut self, more: Vec<(ContactKey, ContactState)>) {
        if more.is_empty() {
            return;
        }
        let more = ContactHistory::from_entries(more).entries;
        let old = std::mem::take(&mut self.entries);
        let mut merged = Vec::with_capacity(old.len() + more.len());
        let mut rest = more.into_iter().peekable();
        for e in old {
            while let Some(m) = rest.next_if(|m| m.0 < e.0) {
                merged.push(m);
            }
            match rest.next_if(|m| m.0 == e.0) {
                Some(m) => merged.push(m),
                None => merged.push(e),
            }
        }
        merged.extend(rest);
        self.entries = merged;
    }

    /// The entries, sorted by key.
    pub fn entries(&self) -> &[(ContactKey, ContactState)] {
        &self.entries
    }

    /// Number of live contacts.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The state of contact `key`, if it was live.
    pub fn get(&self, key: &ContactKey) -> Option<&ContactState> {
        self.entries
            .binary_search_by_key(key, |e| e.0)
            .ok()
            .map(|i| &self.entries[i].1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn state(rng: &mut Rng) -> ContactState {
        ContactState {
            spring: Vector3::new(rng.uniform(), rng.uniform(), rng.uniform()),
            approach_speed: rng.uniform(),
            twist: rng.uniform(),
        }
    }

    fn key(rng: &mut Rng) -> ContactKey {
        let a = (rng.uniform() * 60.0) as u64;
        if rng.uniform() < 0.2 {
            ContactKey::wall(a, (rng.uniform() * 3.0) as usize)
        } else {
            ContactKey::particles(a, (rng.uniform() * 60.0) as u64)
        }
    }

    /// Merging entries into a history gives the history of all the entries in order, a key
    /// held by both (or twice among the new ones) keeping the last state, bit for bit.
    #[test]
    fn merging_is_building_from_all_entries() {
        let mut rng = Rng::new(13);
        for case in 0..300 {
            let old: Vec<_> = (0..case % 50)
                .map(|_| (key(&mut rng), state(&mut rng)))
                .collect();
            let more: Vec<_> = (0..case % 17)
                .map(|_| (key(&mut rng), state(&mut rng)))
                .collect();
            let mut merged = ContactHistory::from_entries(old.clone());
            merged.merge(more.clone());
            let all: Vec<_> = old.into_iter().chain(more).collect();
            assert_eq!(merged, ContactHistory::from_entries(all), "case {case}");
            assert!(merged.entries().windows(2).all(|w| w[0].0 < w[1].0));
        }
    }
}
