//! The particle arrays on the device, declared once in a field table ([`particle_fields!`]):
//! the device struct, its host-side twin for uploads, the empty allocation, the upload, the
//! byte count and the reordering by cell of a list build all come from it.

use super::error::CudaError;
use super::launch::{Kernels, cfg, ptr, zeros};
use super::layout::ParticleView;
use super::upload::{flat_quats, flat3};
use crate::state::Particles;
use cudarc::driver::{CudaSlice, CudaStream, DeviceRepr, ValidAsZeroBits};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::sync::Arc;

/// The field table of the device particle arrays: per element type, the method that reorders
/// that group at a list build, then each field with its values per particle (xyz-interleaved
/// vectors, quaternions as x, y, z, w) and where it comes from: `host`, a field of
/// [`Particles`] of that name, copied both ways; `motion`, such a field that an edit of the
/// motion alone uploads ([`DeviceParticles::upload_motion`]); `device`, derived at the upload
/// from the scene (or the rank's ghosts) and never copied back. `$m!` receives the table.
macro_rules! particle_fields {
    ($m:ident) => {
        $m! {
            f64 gather_f64s {
                scale: 1 host,
                radius: 1 device,
                cn: 1 device,
                ct: 1 device,
                mass: 1 host,
                position: 3 motion,
                velocity: 3 motion,
                angular_velocity: 3 motion,
                orientation: 4 motion,
                force: 3 motion,
                torque: 3 motion,
                inertia: 3 host,
            }
            u32 gather_u32s {
                tmpl: 1 device,
                material: 1 device,
                kind: 1 host,
                // 1 for a ghost (a neighbour rank's particle), 0 for an owned one.
                ghost: 1 device,
                // Contacts at the last evaluation (the dashpot caps' mass splitting).
                contacts: 1 host,
            }
            u64 gather_u64s {
                id: 1 host,
            }
        }
    };
}

/// A [`Particles`] field in the device's flat layout: `width` values per particle.
trait FlatField {
    type Value;
    /// The first `n` particles' values from `flat`.
    fn from_flat(flat: &[Self::Value], n: usize) -> Self;
    /// The values in the flat layout.
    fn to_flat(&self) -> Vec<Self::Value>;
}

macro_rules! flat_scalars {
    ($($t:ty),*) => {$(
        impl FlatField for Vec<$t> {
            type Value = $t;
            fn from_flat(flat: &[$t], n: usize) -> Self {
                flat[..n].to_vec()
            }
            fn to_flat(&self) -> Vec<$t> {
                self.clone()
            }
        }
    )*};
}

flat_scalars!(f64, u32, u64);

impl FlatField for Vec<Vector3<f64>> {
    type Value = f64;
    fn from_flat(flat: &[f64], n: usize) -> Self {
        flat.chunks_exact(3)
            .take(n)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect()
    }
    fn to_flat(&self) -> Vec<f64> {
        flat3(self)
    }
}

impl FlatField for Vec<UnitQuaternion<f64>> {
    type Value = f64;
    fn from_flat(flat: &[f64], n: usize) -> Self {
        // Stored x, y, z, w; the device keeps them unit (`integrate.cu` renormalises).
        flat.chunks_exact(4)
            .take(n)
            .map(|c| UnitQuaternion::new_unchecked(Quaternion::new(c[3], c[0], c[1], c[2])))
            .collect()
    }
    fn to_flat(&self) -> Vec<f64> {
        flat_quats(self)
    }
}

/// `$particles.$field` set from `$arrays.$field` for a `host` or `motion` field; nothing for a
/// `device` one.
macro_rules! copy_host_field {
    (device $particles:ident $arrays:ident $field:ident $n:ident) => {};
    ($origin:ident $particles:ident $arrays:ident $field:ident $n:ident) => {
        $particles.$field = FlatField::from_flat(&$arrays.$field, $n);
    };
}

/// `$device.$field` copied down (`$len` values) for a `host` or `motion` field; empty for a
/// `device` one.
macro_rules! download_field {
    (device $st:ident $device:ident $field:ident $len:expr) => {
        Vec::new()
    };
    ($origin:ident $st:ident $device:ident $field:ident $len:expr) => {{
        let mut v = $st.clone_dtoh(&$device.$field)?;
        v.truncate($len);
        v
    }};
}

/// The upload of `$particles.$field` into `$device.$field` for a `motion` field; nothing for
/// the others.
macro_rules! upload_motion_field {
    (motion $st:ident $particles:ident $device:ident $field:ident) => {
        $st.memcpy_htod(&FlatField::to_flat(&$particles.$field), &mut $device.$field)?;
    };
    ($origin:ident $st:ident $particles:ident $device:ident $field:ident) => {};
}

/// An element type of the particle arrays, reordered by its gather kernel.
pub(super) trait Gather: DeviceRepr + ValidAsZeroBits + Default + Clone + Unpin {
    /// `dst[k·width..] = src[order[k]·width..]` for the `n` rows `k < n` (the rest of `dst`
    /// untouched).
    fn gather_into(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<Self>,
        order: &CudaSlice<u32>,
        dst: &mut CudaSlice<Self>,
    ) -> Result<(), CudaError>;

    /// [`Gather::gather_into`] a new buffer of the `n` rows.
    fn gather(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<Self>,
        order: &CudaSlice<u32>,
    ) -> Result<CudaSlice<Self>, CudaError> {
        let mut dst = zeros::<Self>(st, width * n)?;
        Self::gather_into(k, st, n, width, src, order, &mut dst)?;
        Ok(dst)
    }
}

/// [`Gather`] for an element type whose gather kernel takes a width (`gather_f64`,
/// `gather_u32` of cuda/neighbor.cu).
macro_rules! gather_with_width {
    ($($ty:ty => $kernel:ident),*) => {$(
        impl Gather for $ty {
            fn gather_into(
                k: &Kernels,
                st: &Arc<CudaStream>,
                n: usize,
                width: usize,
                src: &CudaSlice<$ty>,
                order: &CudaSlice<u32>,
                dst: &mut CudaSlice<$ty>,
            ) -> Result<(), CudaError> {
                debug_assert!(dst.len() >= width * n && order.len() >= n);
                let (ni, w) = (n as i32, width as i32);
                // SAFETY: `dst` holds width·n values, `order` n indices of rows of `src`.
                unsafe { k.$kernel(st, cfg(n), &ni, &w, src, dst, order)? };
                Ok(())
            }
        }
    )*};
}

gather_with_width!(f64 => gather_f64, u32 => gather_u32);

impl Gather for u64 {
    fn gather_into(
        k: &Kernels,
        st: &Arc<CudaStream>,
        n: usize,
        width: usize,
        src: &CudaSlice<u64>,
        order: &CudaSlice<u32>,
        dst: &mut CudaSlice<u64>,
    ) -> Result<(), CudaError> {
        debug_assert_eq!(width, 1);
        debug_assert!(dst.len() >= n && order.len() >= n);
        let ni = n as i32;
        // SAFETY: `dst` holds n values, `order` n indices of `src`.
        unsafe { k.gather_u64(st, cfg(n), &ni, src, dst, order)? };
        Ok(())
    }
}

/// The new array of one field after a decomposed run's rebuild on the device: the `n_kept`
/// rows of `src` at `kept`, then the rows of `tail` (from the host), `width` values a row.
fn assemble_field<T: Gather>(
    k: &Kernels,
    st: &Arc<CudaStream>,
    width: usize,
    src: &CudaSlice<T>,
    (kept, n_kept): (&CudaSlice<u32>, usize),
    tail: &[T],
) -> Result<CudaSlice<T>, CudaError> {
    let head = width * n_kept;
    let mut dst = zeros::<T>(st, head + tail.len())?;
    if n_kept > 0 {
        T::gather_into(k, st, n_kept, width, src, kept, &mut dst)?;
    }
    if !tail.is_empty() {
        st.memcpy_htod(tail, &mut dst.slice_mut(head..head + tail.len()))?;
    }
    Ok(dst)
}

/// The rows at `slots` of a `host` or `motion` field, copied down; empty for a `device` one.
macro_rules! download_rows_field {
    (device $ty:ident $k:ident $st:ident $device:ident $field:ident $width:literal $slots:ident $count:ident) => {
        Vec::new()
    };
    ($origin:ident $ty:ident $k:ident $st:ident $device:ident $field:ident $width:literal $slots:ident $count:ident) => {{
        let rows = <$ty as Gather>::gather($k, $st, $count, $width, &$device.$field, $slots)?;
        let mut v = $st.clone_dtoh(&rows)?;
        v.truncate($width * $count);
        v
    }};
}

/// `v`, or one default value when it is empty (every device buffer has an address).
pub(super) fn at_least_one<T: Default>(mut v: Vec<T>) -> Vec<T> {
    if v.is_empty() {
        v.push(T::default());
    }
    v
}

macro_rules! declare_particles {
    ($($ty:ident $gather:ident {
        $($field:ident: $width:literal $origin:ident),* $(,)?
    })*) => {
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

            /// The `host` and `motion` arrays copied down, `width · n` values each; the
            /// `device` ones, derived at the upload, are left empty.
            pub(super) fn download(
                &self,
                st: &Arc<CudaStream>,
            ) -> Result<HostParticleArrays, CudaError> {
                let n = self.n;
                Ok(HostParticleArrays {
                    $($($field: download_field!($origin st self $field ($width * n)),)*)*
                })
            }

            /// The `host` and `motion` arrays of the `count` particles at `slots`, copied
            /// down (gathered on the device first), `width · count` values each; the
            /// `device` ones are left empty.
            pub(super) fn download_rows(
                &self,
                k: &Kernels,
                st: &Arc<CudaStream>,
                slots: &CudaSlice<u32>,
                count: usize,
            ) -> Result<HostParticleArrays, CudaError> {
                Ok(HostParticleArrays {
                    $($($field: download_rows_field!(
                        $origin $ty k st self $field $width slots count
                    ),)*)*
                })
            }

            /// The arrays after a decomposed run's rebuild on the device: the `n_kept`
            /// particles of `old` at slots `kept` (gathered on the device), then the
            /// `n_tail` of `tail` (from the host: arrivals and ghosts).
            pub(super) fn assemble(
                k: &Kernels,
                st: &Arc<CudaStream>,
                old: &DeviceParticles,
                (kept, n_kept): (&CudaSlice<u32>, usize),
                tail: HostParticleArrays,
                n_tail: usize,
            ) -> Result<Self, CudaError> {
                Ok(DeviceParticles {
                    n: n_kept + n_tail,
                    $($($field: assemble_field::<$ty>(
                        k, st, $width, &old.$field, (kept, n_kept), &tail.$field
                    )?,)*)*
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

impl HostParticleArrays {
    /// The `host` fields of the table written into `particles`, `n` of them (the `device`
    /// fields, derived at the upload, are dropped).
    pub(super) fn copy_into(&self, particles: &mut Particles, n: usize) {
        macro_rules! copy_all {
            ($($ty:ident $gather:ident {
                $($field:ident: $width:literal $origin:ident),* $(,)?
            })*) => {
                $($(copy_host_field!($origin particles self $field n);)*)*
            };
        }
        particle_fields!(copy_all);
    }
}

impl DeviceParticles {
    /// The `motion` fields of the table uploaded from `particles`, which hold the device's
    /// particles in its order (an edit that changed nothing else).
    pub(super) fn upload_motion(
        &mut self,
        st: &Arc<CudaStream>,
        particles: &Particles,
    ) -> Result<(), CudaError> {
        let device = self;
        macro_rules! upload_all {
            ($($ty:ident $gather:ident {
                $($field:ident: $width:literal $origin:ident),* $(,)?
            })*) => {
                $($(upload_motion_field!($origin st particles device $field);)*)*
            };
        }
        particle_fields!(upload_all);
        Ok(())
    }
}

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
