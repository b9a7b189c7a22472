//! What the CUDA installation offers, queried without panicking.
//!
//! cudarc loads `libcuda` and `libnvrtc` at run time, so the binary builds and runs on machines
//! without CUDA. Detection checks that each library is present before calling into it (cudarc
//! panics when a library it is asked to use is missing), and never panics itself: a machine
//! without a usable GPU simply gets the CPU backend, with the reason in the log.

use serde::Serialize;

/// A GPU as the driver reports it.
#[derive(Clone, Debug, Serialize)]
pub struct GpuInfo {
    /// Device ordinal.
    pub ordinal: usize,
    /// Marketing name, e.g. "NVIDIA H100 80GB HBM3".
    pub name: String,
    /// Compute capability (major, minor); NVRTC compiles for `sm_<major><minor>`.
    pub compute_capability: (i32, i32),
    /// Total device memory in bytes.
    pub total_memory: usize,
}

/// What the CUDA installation offers.
#[derive(Clone, Debug, Serialize)]
pub struct CudaInfo {
    /// Driver API version as `major.minor` (e.g. 13.0), when libcuda loads.
    pub driver_version: Option<String>,
    /// NVRTC version as `major.minor`, when libnvrtc loads.
    pub nvrtc_version: Option<String>,
    /// Visible GPUs.
    pub gpus: Vec<GpuInfo>,
    /// Why CUDA cannot be used, when it cannot.
    pub unavailable: Option<String>,
}

/// Queries the driver and NVRTC without panicking.
pub fn cuda_info() -> CudaInfo {
    let mut info = CudaInfo {
        driver_version: None,
        nvrtc_version: None,
        gpus: Vec::new(),
        unavailable: None,
    };
    // SAFETY: these only try to open the shared libraries.
    let (has_driver, has_nvrtc) = unsafe {
        (
            cudarc::driver::sys::is_culib_present(),
            cudarc::nvrtc::sys::is_culib_present(),
        )
    };
    if has_nvrtc {
        let (mut major, mut minor) = (0, 0);
        // SAFETY: the library is present; nvrtcVersion writes two ints.
        let status = unsafe { cudarc::nvrtc::sys::nvrtcVersion(&mut major, &mut minor) };
        if status == cudarc::nvrtc::sys::nvrtcResult::NVRTC_SUCCESS {
            info.nvrtc_version = Some(format!("{major}.{minor}"));
        }
    }
    if !has_driver {
        info.unavailable = Some("libcuda (the NVIDIA driver) is not installed".into());
        return info;
    }
    let mut version = 0;
    // SAFETY: the library is present; cuDriverGetVersion writes one int.
    if unsafe { cudarc::driver::sys::cuDriverGetVersion(&mut version) }
        == cudarc::driver::sys::CUresult::CUDA_SUCCESS
    {
        info.driver_version = Some(format!("{}.{}", version / 1000, (version % 1000) / 10));
    }
    let count = match cudarc::driver::CudaContext::device_count() {
        Ok(n) => n,
        Err(e) => {
            info.unavailable = Some(format!("the CUDA driver reports an error: {e}"));
            return info;
        }
    };
    for ordinal in 0..count.max(0) as usize {
        match cudarc::driver::CudaContext::new(ordinal) {
            Ok(ctx) => info.gpus.push(GpuInfo {
                ordinal,
                name: ctx.name().unwrap_or_else(|e| format!("unknown ({e})")),
                compute_capability: ctx.compute_capability().unwrap_or((0, 0)),
                total_memory: ctx.total_mem().unwrap_or(0),
            }),
            Err(e) => {
                info.unavailable = Some(format!("GPU {ordinal} cannot be opened: {e}"));
            }
        }
    }
    if info.gpus.is_empty() && info.unavailable.is_none() {
        info.unavailable = Some("the driver sees no GPU".into());
    }
    if info.nvrtc_version.is_none() && info.unavailable.is_none() {
        info.unavailable = Some("libnvrtc (NVRTC, to compile the kernels) is not installed".into());
    }
    info
}
