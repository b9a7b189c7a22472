//! What a decomposed GPU run's rebuild on the device copies down (docs/design.md §6,
//! [`super::exchange`]): each slot's ghost flag, global id and centroid, the particles at given
//! slots, and the leaving particles with the live contact history they are members of, packed
//! on the device.

use super::CudaSimulation;
use super::error::CudaError;
use super::launch::{cfg, zeros};
use super::layout::{CONTACT_LIVE, HISTORY_WIDTH, history_state};
use super::particles::Gather;
use crate::contact::{ContactKey, ContactState};
use crate::state::Particles;
use nalgebra::Vector3;

/// `v` cut to `n` values.
pub(super) fn first<T>(mut v: Vec<T>, n: usize) -> Vec<T> {
    v.truncate(n);
    v
}

impl CudaSimulation {
    /// What the host decides a rebuild from: each slot's ghost flag, global id and centroid.
    #[allow(clippy::type_complexity)]
    pub(super) fn centroids(&self) -> Result<(Vec<u32>, Vec<u64>, Vec<Vector3<f64>>), CudaError> {
        let (st, p, n) = (&self.gpu.stream, &self.particles, self.particles.n);
        let position = first(st.clone_dtoh(&p.position)?, 3 * n)
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect();
        Ok((
            first(st.clone_dtoh(&p.ghost)?, n),
            first(st.clone_dtoh(&p.id)?, n),
            position,
        ))
    }

    /// The particles at device slots `slots`, copied down (host fields only).
    pub(super) fn download_particles(&self, slots: &[u32]) -> Result<Particles, CudaError> {
        let mut p = Particles::default();
        if slots.is_empty() {
            return Ok(p);
        }
        let st = &self.gpu.stream;
        let d = st.clone_htod(slots)?;
        let rows = self
            .particles
            .download_rows(&self.gpu.k, st, &d, slots.len())?;
        rows.copy_into(&mut p, slots.len());
        Ok(p)
    }

    /// The particles at device slots `slots` (leaving this rank) and the live contact history
    /// they are members of: their pairs, packed on the device, and their walls.
    pub(super) fn leavers_state(
        &self,
        slots: &[u32],
    ) -> Result<(Particles, Vec<(ContactKey, ContactState)>), CudaError> {
        let p = self.download_particles(slots)?;
        let mut entries = Vec::new();
        if slots.is_empty() {
            return Ok((p, entries));
        }
        let st = &self.gpu.stream;
        let k = &self.gpu.k;
        let count = slots.len();
        let ci = count as i32;
        let d = st.clone_htod(slots)?;
        if let Some(list) = &self.pairs.list {
            let mut counts = zeros::<u32>(st, count)?;
            // SAFETY: `d` holds count slots below n, the list's references cover n slots.
            unsafe {
                k.count_live_refs(
                    st,
                    cfg(count),
                    &ci,
                    &d,
                    &list.ref_offset,
                    &list.refs,
                    &list.contact,
                    &mut counts,
                )?;
            }
            let counts = first(st.clone_dtoh(&counts)?, count);
            let mut offset = Vec::with_capacity(count);
            let mut rows = 0u32;
            for c in &counts {
                offset.push(rows);
                rows += c;
            }
            let rows = rows as usize;
            if rows > 0 {
                let offset = st.clone_htod(&offset)?;
                let mut a = zeros::<u64>(st, rows)?;
                let mut b = zeros::<u64>(st, rows)?;
                let mut spring = zeros::<f64>(st, HISTORY_WIDTH * rows)?;
                // SAFETY: as above; the outputs hold the rows the scanned counts reach.
                unsafe {
                    k.pack_live_refs(
                        st,
                        cfg(count),
                        &ci,
                        &d,
                        &list.ref_offset,
                        &list.refs,
                        &list.pairs,
                        &self.particles.id,
                        &list.contact,
                        &list.spring,
                        &offset,
                        &mut a,
                        &mut b,
                        &mut spring,
                    )?;
                }
                let (a, b) = (
                    first(st.clone_dtoh(&a)?, rows),
                    first(st.clone_dtoh(&b)?, rows),
                );
                let spring = first(st.clone_dtoh(&spring)?, HISTORY_WIDTH * rows);
                for r in 0..rows {
                    let s = &spring[HISTORY_WIDTH * r..HISTORY_WIDTH * (r + 1)];
                    entries.push((ContactKey::particles(a[r], b[r]), history_state(s)));
                }
            }
        }
        if let Some(w) = self.walls.as_ref().filter(|w| w.n > 0) {
            let flags = first(
                st.clone_dtoh(&u32::gather(k, st, count, w.n, &w.contact, &d)?)?,
                count * w.n,
            );
            let springs = first(
                st.clone_dtoh(&f64::gather(
                    k,
                    st,
                    count,
                    HISTORY_WIDTH * w.n,
                    &w.spring_in,
                    &d,
                )?)?,
                HISTORY_WIDTH * w.n * count,
            );
            for (m, &g) in p.id.iter().enumerate() {
                for wall in 0..w.n {
                    let s = m * w.n + wall;
                    if flags[s] == CONTACT_LIVE {
                        let spring = &springs[HISTORY_WIDTH * s..HISTORY_WIDTH * (s + 1)];
                        entries.push((ContactKey::wall(g, wall), history_state(spring)));
                    }
                }
            }
        }
        Ok((p, entries))
    }
}
