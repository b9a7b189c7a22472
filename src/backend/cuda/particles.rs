//! The particle arrays on the device, declared once in a field table ([`particle_fields!`]):
//! the device struct, its host-side twin for uploads, the empty allocation, the upload, the
//! byte count and the reordering by cell of a list build all come from it.

use super::error::CudaError;
use super::launch::{Kernels, cfg, ptr, zeros};
use super::layout::ParticleView;
use cudarc::driver::{CudaSlice, CudaStream, DeviceRepr, ValidAsZeroBits};
use std::sync::Arc;

/// The field table of the device particle arrays: per element type, the method that reorders
/// that group at a list build, then each field with its values per particle (xyz-interleaved
/// vectors, quaternions as x, y, z, w). `$m!` receives the table.
macro_rules! particle_fields {
    ($m:ident) => {
        $m! {
            f64 gather_f64s {
                scale: 1,
                radius: 1,
                cn: 1,
                ct: 1,
                mass: 1,
                position: 3,
                velocity: 3,
                angular_velocity: 3,
                orientation: 4,
                force: 3,
                torque: 3,
                inertia: 3,
            }
            u32 gather_u32s {
                tmpl: 1,
                material: 1,
                kind: 1,
                // 1 for a ghost (a neighbour rank's particle), 0 for an owned one.
                ghost: 1,
                // Contacts at the last evaluation (the dashpot caps' mass splitting).
                contacts: 1,
            }
            u64 gather_u64s {
                id: 1,
            }
        }
    };
}

/// An element type of the particle arrays, reordered by its gather kernel.
pub(super) trait Gather: DeviceRepr + ValidAsZeroBits + Default + Clone {
    /// `dst[k·width..] = src[order[k]·width..]` for the `n` particles, into a new buffer.
    fn gather(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<Self>,
        order: &CudaSlice<u32>,
    ) -> Result<CudaSlice<Self>, CudaError>;
}

impl Gather for f64 {
    fn gather(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<f64>,
        order: &CudaSlice<u32>,
    ) -> Result<CudaSlice<f64>, CudaError> {
        let mut dst = zeros::<f64>(st, width * n)?;
        let (ni, w) = (n as i32, width as i32);
        // SAFETY: both buffers hold width·n values, `order` n indices below n.
        unsafe { k.gather_f64(st, cfg(n), &ni, &w, src, &mut dst, order)? };
        Ok(dst)
    }
}

impl Gather for u32 {
    fn gather(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<u32>,
        order: &CudaSlice<u32>,
    ) -> Result<CudaSlice<u32>, CudaError> {
        debug_assert_eq!(width, 1);
        let mut dst = zeros::<u32>(st, n)?;
        let ni = n as i32;
        // SAFETY: both buffers hold n values, `order` n indices below n.
        unsafe { k.gather_u32(st, cfg(n), &ni, src, &mut dst, order)? };
        Ok(dst)
    }
}

impl Gather for u64 {
    fn gather(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<u64>,
        order: &CudaSlice<u32>,
    ) -> Result<CudaSlice<u64>, CudaError> {
        debug_assert_eq!(width, 1);
        let mut dst = zeros::<u64>(st, n)?;
        let ni = n as i32;
        // SAFETY: both buffers hold n values, `order` n indices below n.
        unsafe { k.gather_u64(st, cfg(n), &ni, src, &mut dst, order)? };
        Ok(dst)
    }
}

/// `v`, or one default value when it is empty (every device buffer has an address).
fn at_least_one<T: Default>(mut v: Vec<T>) -> Vec<T> {
    if v.is_empty() {
        v.push(T::default());
    }
    v
}

macro_rules! declare_particles {
    ($($ty:ident $gather:ident { $($field:ident: $width:literal),* $(,)? })*) => {
        /// Particle arrays on the device: `n` slots (at least one value per buffer).
        pub(super) struct DeviceParticles {
            /// Slots in use (owned particles, then a decomposed run's ghosts).
            pub(super) n: usize,
            $($(pub(super) $field: CudaSlice<$ty>,)*)*
        }

        /// The particle arrays on the host, in the device's layout, for an upload.
        pub(super) struct HostParticleArrays {
            $($(pub(super) $field: Vec<$ty>,)*)*
        }

        impl DeviceParticles {
            /// Device bytes per particle slot, all arrays together.
            pub(super) const BYTES_PER_PARTICLE: usize =
                0 $($(+ $width * std::mem::size_of::<$ty>())*)*;

            /// No particles (one zero per buffer).
            pub(super) fn empty(st: &Arc<CudaStream>) -> Result<Self, CudaError> {
                Ok(DeviceParticles {
                    n: 0,
                    $($($field: st.alloc_zeros::<$ty>(1)?,)*)*
                })
            }

            /// The `n` particles of `host` copied up.
            pub(super) fn upload(
                st: &Arc<CudaStream>,
                n: usize,
                host: HostParticleArrays,
            ) -> Result<Self, CudaError> {
                Ok(DeviceParticles {
                    n,
                    $($($field: st.clone_htod(&at_least_one(host.$field))?,)*)*
                })
            }

            /// Bytes of device memory held by the arrays.
            pub(super) fn bytes(&self) -> usize {
                0 $($(+ self.$field.len() * std::mem::size_of::<$ty>())*)*
            }

            $(
                #[doc = concat!("Reorders the ", stringify!($ty), " arrays by `order` (slot k \
                    takes the values of slot order[k]), in the table's order.")]
                pub(super) fn $gather(
                    &mut self,
                    k: &Kernels,
                    st: &Arc<CudaStream>,
                    order: &CudaSlice<u32>,
                ) -> Result<(), CudaError> {
                    $(
                        self.$field =
                            <$ty as Gather>::gather(k, st, self.n, $width, &self.$field, order)?;
                    )*
                    Ok(())
                }
            )*
        }
    };
}

particle_fields!(declare_particles);

impl DeviceParticles {
    /// The device pointers the contact kernels read, valid until the arrays are reallocated
    /// (an upload, a list build's reordering).
    pub(super) fn view(&self, st: &CudaStream) -> ParticleView {
        ParticleView {
            position: ptr(&self.position, st),
            velocity: ptr(&self.velocity, st),
            angular_velocity: ptr(&self.angular_velocity, st),
            orientation: ptr(&self.orientation, st),
            mass: ptr(&self.mass, st),
            inertia: ptr(&self.inertia, st),
            scale: ptr(&self.scale, st),
            radius: ptr(&self.radius, st),
            cn: ptr(&self.cn, st),
            ct: ptr(&self.ct, st),
            tmpl: ptr(&self.tmpl, st),
            material: ptr(&self.material, st),
            contacts: ptr(&self.contacts, st),
        }
    }
}
