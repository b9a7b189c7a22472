//! The contact history between the device's slot layout and the host's [`ContactHistory`]:
//! the last evaluation's pair and wall outcomes, copied down ([`PairOutcomes`],
//! [`WallOutcomes`]), gathered into the history, the contact counts, the elastic energy and the
//! walls' forces ([`gather_contacts`], for `sync_host`); and the history laid out per slot for
//! the next list build ([`history_rows`], for `upload_from_host`).
//!
//! Both run at every rebuild of a decomposed GPU run, on a million pairs for 1e5 particles a
//! rank, so neither sorts or hashes what it can walk in order: the lists name a pair's lower-id
//! member first and keep each particle's references sorted by partner id (`sort_refs` of
//! cuda/neighbor.cu), and the host's history is sorted by key.

use super::layout::{CONTACT_LIVE, HISTORY_WIDTH, history_record, history_state};
use crate::contact::{ContactHistory, ContactKey};
use crate::state::id_order;
use nalgebra::Vector3;

/// The last evaluation's outcome of every listed pair, copied down: the members' slots (the
/// lower-id member first), the contact flag ([`CONTACT_LIVE`], `CONTACT_FAILED` | status, or 0),
/// the spring ([`HISTORY_WIDTH`] values) and the elastic energy; and each slot's references
/// into the list (`ref_offset[i]..ref_offset[i + 1]` of `refs`; a reference `r` names pair
/// `r >> 1`, whose second member the slot is when `r & 1`), sorted by partner id.
pub(super) struct PairOutcomes {
    pub(super) slots: Vec<[usize; 2]>,
    pub(super) contact: Vec<u32>,
    pub(super) spring: Vec<f64>,
    pub(super) energy: Vec<f64>,
    pub(super) ref_offset: Vec<u32>,
    pub(super) refs: Vec<u32>,
}

impl PairOutcomes {
    /// Pair `k`'s spring.
    pub(super) fn spring(&self, k: usize) -> &[f64] {
        &self.spring[HISTORY_WIDTH * k..HISTORY_WIDTH * (k + 1)]
    }

    /// The pairs of slot `i` as their first (lower-id) member, by partner id.
    fn first_of(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.refs[self.ref_offset[i] as usize..self.ref_offset[i + 1] as usize]
            .iter()
            .filter(|&&r| r & 1 == 0)
            .map(|&r| (r >> 1) as usize)
    }
}

/// The last evaluation's wall outcomes, copied down: per particle slot `i` and wall `k`, at
/// `s = i · walls + k`, the contact flag, the spring and the force on the wall; per particle the
/// elastic energy of its wall contacts.
pub(super) struct WallOutcomes {
    pub(super) walls: usize,
    /// [`CONTACT_LIVE`], `CONTACT_FAILED` | status, or 0.
    pub(super) contact: Vec<u32>,
    pub(super) spring: Vec<f64>,
    /// Per particle.
    pub(super) energy: Vec<f64>,
    pub(super) per_wall_force: Vec<f64>,
}

impl WallOutcomes {
    /// The slot of particle `i` and wall `k`.
    pub(super) fn slot(&self, i: usize, k: usize) -> usize {
        i * self.walls + k
    }

    /// The spring of slot `s`.
    pub(super) fn spring(&self, s: usize) -> &[f64] {
        &self.spring[HISTORY_WIDTH * s..HISTORY_WIDTH * (s + 1)]
    }

    /// The force on the wall of slot `s`.
    pub(super) fn force(&self, s: usize) -> Vector3<f64> {
        let f = &self.per_wall_force[3 * s..3 * s + 3];
        Vector3::new(f[0], f[1], f[2])
    }
}

/// What [`gather_contacts`] finds in the outcomes.
#[derive(Debug, PartialEq)]
pub(super) struct GatheredContacts {
    pub(super) history: ContactHistory,
    /// Pair contacts whose lower-id member is owned (a pair across two ranks counts once).
    pub(super) contacts: u64,
    pub(super) wall_contacts: u64,
    /// The pairs' elastic energy (those counted) and the owned particles' wall contacts', and
    /// the walls' forces, as exact sums.
    pub(super) sums: crate::exact_sum::DiagnosticSums,
}

/// The history, counts, elastic energy and walls' forces of slots with global ids `ids` (a
/// decomposed run's `ghost`s among them) from the device's outcomes.
///
/// The energy and the walls' forces are summed in global id order, each pair under its
/// lower-id member by partner id, then each particle's walls, as the CPU's reduction sums them
/// (`Particles::id_order`): the device's slot order is that of its last list build, which
/// depends on who built it and when, and sums in that order changed in their last bits from
/// run to run while the trajectory did not. Walking the slots in id order and each one's
/// references as first member visits the pairs in that order without sorting them, and gives
/// the history's entries in key order (a wall's key after its particle's pairs), except the
/// entries of pairs whose first member is a ghost, a tail that [`ContactHistory::from_entries`]
/// merges.
pub(super) fn gather_contacts(
    ids: &[u64],
    ghost: &[bool],
    pairs: Option<&PairOutcomes>,
    walls: Option<&WallOutcomes>,
) -> GatheredContacts {
    let order = id_order(ids).unwrap_or_else(|| (0..ids.len()).collect());
    let (mut contacts, mut wall_contacts) = (0u64, 0u64);
    let mut sums = crate::exact_sum::DiagnosticSums::new(walls.map_or(0, |w| w.walls));
    let mut entries = Vec::new();
    let mut ghost_entries = Vec::new();
    for &i in &order {
        let owned = !ghost[i];
        if let Some(out) = pairs {
            for k in out.first_of(i) {
                if owned {
                    sums.elastic.add(out.energy[k]);
                }
                if out.contact[k] == CONTACT_LIVE {
                    contacts += u64::from(owned);
                    let entry = (
                        ContactKey::particles(ids[i], ids[out.slots[k][1]]),
                        history_state(out.spring(k)),
                    );
                    if owned {
                        entries.push(entry);
                    } else {
                        ghost_entries.push(entry);
                    }
                }
            }
        }
        if let Some(w) = walls.filter(|_| owned) {
            for k in 0..w.walls {
                let s = w.slot(i, k);
                if w.contact[s] == CONTACT_LIVE {
                    entries.push((ContactKey::wall(ids[i], k), history_state(w.spring(s))));
                }
            }
        }
    }
    entries.append(&mut ghost_entries);
    if let Some(w) = walls {
        for &i in order.iter().filter(|&&i| !ghost[i]) {
            sums.elastic.add(w.energy[i]);
            for k in 0..w.walls {
                let s = w.slot(i, k);
                if w.contact[s] == CONTACT_LIVE {
                    wall_contacts += 1;
                    sums.add_wall_force(k, &w.force(s));
                }
            }
        }
    }
    GatheredContacts {
        history: ContactHistory::from_entries(entries),
        contacts,
        wall_contacts,
        sums,
    }
}

/// The history laid out for the device: per slot its pairs as the key's first member
/// (`offset[i]..offset[i + 1]` of `partner` and `spring`, in key order), and per slot and wall
/// the wall contact's spring (`wall_spring`, zero where there is none).
#[derive(Debug, PartialEq)]
pub(super) struct HistoryRows {
    pub(super) offset: Vec<u32>,
    /// At least one value (every device buffer has an address): `u64::MAX` when empty.
    pub(super) partner: Vec<u64>,
    pub(super) spring: Vec<f64>,
    pub(super) wall_spring: Vec<f64>,
}

/// `history` laid out per slot of particles with global ids `ids` and `walls` walls
/// ([`HistoryRows`]). The entries are sorted by key, so each one's slot comes from one merge
/// with the ids sorted; entries of particles not among `ids`, and of walls past `walls`, are
/// left out. (An id held twice, by an owned particle and its own periodic image as a ghost,
/// which boxes at least two halos wide rule out, would give the row to the lower slot.)
pub(super) fn history_rows(ids: &[u64], history: &ContactHistory, walls: usize) -> HistoryRows {
    let n = ids.len();
    let entries = history.entries();
    let mut by_id: Vec<(u64, u32)> = ids
        .iter()
        .enumerate()
        .map(|(i, &g)| (g, i as u32))
        .collect();
    by_id.sort_unstable();
    let mut cursor = 0;
    let slot_of: Vec<Option<usize>> = entries
        .iter()
        .map(|(key, _)| {
            while cursor < by_id.len() && by_id[cursor].0 < key.a {
                cursor += 1;
            }
            by_id
                .get(cursor)
                .filter(|(g, _)| *g == key.a)
                .map(|&(_, i)| i as usize)
        })
        .collect();
    let mut wall_spring = vec![0.0f64; (n * walls * HISTORY_WIDTH).max(1)];
    let mut offset = vec![0u32; n + 1];
    for ((key, _), slot) in entries.iter().zip(&slot_of) {
        if let (Some(i), None) = (slot, key.wall_index()) {
            offset[i + 1] += 1;
        }
    }
    for i in 0..n {
        offset[i + 1] += offset[i];
    }
    let rows = offset[n] as usize;
    let mut fill: Vec<u32> = offset[..n].to_vec();
    let mut partner = vec![u64::MAX; rows.max(1)];
    let mut spring = vec![0.0f64; HISTORY_WIDTH * rows.max(1)];
    for ((key, state), slot) in entries.iter().zip(&slot_of) {
        let Some(i) = *slot else {
            continue;
        };
        match key.wall_index() {
            Some(k) if k < walls => {
                let s = (i * walls + k) * HISTORY_WIDTH;
                wall_spring[s..s + HISTORY_WIDTH].copy_from_slice(&history_record(state));
            }
            Some(_) => {}
            None => {
                let m = fill[i] as usize;
                fill[i] += 1;
                partner[m] = key.b;
                spring[HISTORY_WIDTH * m..HISTORY_WIDTH * (m + 1)]
                    .copy_from_slice(&history_record(state));
            }
        }
    }
    HistoryRows {
        offset,
        partner,
        spring,
        wall_spring,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::ContactState;
    use crate::rng::Rng;
    use std::collections::HashMap;

    /// A random decomposed rank's outcomes: `n` slots with shuffled unique ids, a fifth of them
    /// ghosts, candidate pairs in a shuffled list (no two ghosts), flags live, failed or none,
    /// and two walls.
    fn outcomes(seed: u64, n: usize) -> (Vec<u64>, Vec<bool>, PairOutcomes, WallOutcomes) {
        let mut rng = Rng::new(seed);
        let mut ids: Vec<u64> = (0..n as u64).map(|i| 3 * i + 7).collect();
        for i in (1..n).rev() {
            ids.swap(i, rng.next_u64() as usize % (i + 1));
        }
        let ghost: Vec<bool> = (0..n).map(|_| rng.uniform() < 0.2).collect();
        let mut slots = Vec::new();
        for a in 0..n {
            for b in 0..n {
                if ids[a] < ids[b] && !(ghost[a] && ghost[b]) && rng.uniform() < 0.15 {
                    slots.push([a, b]);
                }
            }
        }
        for i in (1..slots.len()).rev() {
            slots.swap(i, rng.next_u64() as usize % (i + 1));
        }
        let np = slots.len();
        let flag = |rng: &mut Rng| match rng.next_u64() % 4 {
            0 | 1 => CONTACT_LIVE,
            2 => 0,
            _ => 0x100 | 3,
        };
        let contact: Vec<u32> = (0..np).map(|_| flag(&mut rng)).collect();
        let spring: Vec<f64> = (0..HISTORY_WIDTH * np).map(|_| rng.normal()).collect();
        let energy: Vec<f64> = (0..np).map(|_| rng.range(0.0, 1e-3)).collect();
        // References per slot, sorted by partner id, as `sort_refs` leaves them.
        let mut per: Vec<Vec<(u64, u32)>> = vec![Vec::new(); n];
        for (k, &[a, b]) in slots.iter().enumerate() {
            per[a].push((ids[b], 2 * k as u32));
            per[b].push((ids[a], 2 * k as u32 + 1));
        }
        let mut ref_offset = vec![0u32];
        let mut refs = Vec::new();
        for mut row in per {
            row.sort_unstable();
            refs.extend(row.iter().map(|&(_, r)| r));
            ref_offset.push(refs.len() as u32);
        }
        let walls = 2;
        let wall_contact: Vec<u32> = (0..n * walls).map(|_| flag(&mut rng)).collect();
        let wall_spring: Vec<f64> = (0..HISTORY_WIDTH * n * walls)
            .map(|_| rng.normal())
            .collect();
        let wall_energy: Vec<f64> = (0..n).map(|_| rng.range(0.0, 1e-3)).collect();
        let per_wall_force: Vec<f64> = (0..3 * n * walls).map(|_| rng.normal()).collect();
        (
            ids,
            ghost,
            PairOutcomes {
                slots,
                contact,
                spring,
                energy,
                ref_offset,
                refs,
            },
            WallOutcomes {
                walls,
                contact: wall_contact,
                spring: wall_spring,
                energy: wall_energy,
                per_wall_force,
            },
        )
    }

    /// The gathering as it was written before: every pair's energy sorted by its ids, every
    /// live contact collected in list order and the whole history sorted.
    fn gathered_by_sorting(
        ids: &[u64],
        ghost: &[bool],
        pairs: &PairOutcomes,
        walls: &WallOutcomes,
    ) -> GatheredContacts {
        let (mut contacts, mut wall_contacts) = (0u64, 0u64);
        let mut sums = crate::exact_sum::DiagnosticSums::new(walls.walls);
        let mut entries = Vec::new();
        let mut pair_energy = Vec::new();
        for (k, &[a, b]) in pairs.slots.iter().enumerate() {
            let counted = !ghost[a];
            if counted {
                pair_energy.push((ids[a].min(ids[b]), ids[a].max(ids[b]), pairs.energy[k]));
            }
            if pairs.contact[k] == CONTACT_LIVE {
                contacts += u64::from(counted);
                entries.push((
                    ContactKey::particles(ids[a], ids[b]),
                    history_state(pairs.spring(k)),
                ));
            }
        }
        pair_energy.sort_unstable_by_key(|&(a, b, _)| (a, b));
        // Summed in reverse: exact sums do not depend on the order.
        for (_, _, e) in pair_energy.iter().rev() {
            sums.elastic.add(*e);
        }
        for i in id_order(ids).unwrap_or_else(|| (0..ids.len()).collect()) {
            if ghost[i] {
                continue;
            }
            sums.elastic.add(walls.energy[i]);
            for k in 0..walls.walls {
                let s = walls.slot(i, k);
                if walls.contact[s] == CONTACT_LIVE {
                    wall_contacts += 1;
                    sums.add_wall_force(k, &walls.force(s));
                    entries.push((ContactKey::wall(ids[i], k), history_state(walls.spring(s))));
                }
            }
        }
        GatheredContacts {
            history: ContactHistory::from_entries(entries),
            contacts,
            wall_contacts,
            sums,
        }
    }

    #[test]
    fn gathering_in_id_order_equals_sorting_every_pair() {
        for seed in 0..20 {
            let (ids, ghost, pairs, walls) = outcomes(seed, 60);
            let got = gather_contacts(&ids, &ghost, Some(&pairs), Some(&walls));
            let want = gathered_by_sorting(&ids, &ghost, &pairs, &walls);
            // Bit for bit: the same exact sums, the same entries.
            assert_eq!(
                got.sums.elastic.value().to_bits(),
                want.sums.elastic.value().to_bits(),
                "seed {seed}"
            );
            assert_eq!(got, want, "seed {seed}");
            assert!(
                got.history.len() > 100 && got.contacts > 50,
                "seed {seed}: too few"
            );
        }
        // A run without ghosts or walls, its slots already in id order.
        let ids: Vec<u64> = (0..40).collect();
        let got = gather_contacts(&ids, &[false; 40], None, None);
        assert!(
            got.history.is_empty()
                && got.sums.elastic.value() == 0.0
                && got.sums.wall_forces.is_empty()
        );
    }

    /// The layout as it was written before: a hash map from id to slot and a row per slot.
    fn rows_by_hashing(ids: &[u64], history: &ContactHistory, walls: usize) -> HistoryRows {
        let n = ids.len();
        let index: HashMap<u64, usize> = ids.iter().enumerate().map(|(i, &g)| (g, i)).collect();
        let mut per: Vec<Vec<(u64, [f64; HISTORY_WIDTH])>> = vec![Vec::new(); n];
        let mut wall_spring = vec![0.0f64; (n * walls * HISTORY_WIDTH).max(1)];
        for (key, state) in history.entries() {
            let Some(&i) = index.get(&key.a) else {
                continue;
            };
            match key.wall_index() {
                Some(k) if k < walls => {
                    let slot = (i * walls + k) * HISTORY_WIDTH;
                    wall_spring[slot..slot + HISTORY_WIDTH].copy_from_slice(&history_record(state));
                }
                Some(_) => {}
                None => per[i].push((key.b, history_record(state))),
            }
        }
        let mut offset = vec![0u32; n + 1];
        let (mut partner, mut spring) = (Vec::new(), Vec::new());
        for i in 0..n {
            for (b, sp) in &per[i] {
                partner.push(*b);
                spring.extend_from_slice(sp);
            }
            offset[i + 1] = partner.len() as u32;
        }
        if partner.is_empty() {
            partner.push(u64::MAX);
            spring.extend_from_slice(&[0.0; HISTORY_WIDTH]);
        }
        HistoryRows {
            offset,
            partner,
            spring,
            wall_spring,
        }
    }

    #[test]
    fn rows_by_merging_equal_rows_by_hashing() {
        for seed in 0..20 {
            let (ids, ghost, pairs, walls) = outcomes(seed, 60);
            let mut history = gather_contacts(&ids, &ghost, Some(&pairs), Some(&walls)).history;
            // Entries the upload must leave out: a particle that is not here, a wall past the
            // scene's.
            let stray = ContactState {
                spring: Vector3::new(1.0, 2.0, 3.0),
                approach_speed: 0.5,
                twist: 0.1,
            };
            let mut entries = history.entries().to_vec();
            entries.push((ContactKey::particles(1, 2), stray));
            entries.push((ContactKey::wall(ids[0], 5), stray));
            history = ContactHistory::from_entries(entries);
            let got = history_rows(&ids, &history, walls.walls);
            assert_eq!(
                got,
                rows_by_hashing(&ids, &history, walls.walls),
                "seed {seed}"
            );
            assert!(got.offset[ids.len()] > 50, "seed {seed}: too few rows");
        }
        let empty = history_rows(&[4, 2, 9], &ContactHistory::default(), 1);
        assert_eq!(
            empty,
            rows_by_hashing(&[4, 2, 9], &ContactHistory::default(), 1)
        );
    }
}
