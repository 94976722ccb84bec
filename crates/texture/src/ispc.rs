//! Intel's ISPC texture compressor (`intel_tex_2`) for BC1, BC3 and BC7, run at the process's
//! kernel instruction-set level (`base::isa`): the crate's library holds each kernel compiled for
//! SSE2, SSE4, AVX2 and AVX-512 and picks the CPU's best; below AVX-512 cirrus calls the level's
//! kernel by its own symbol.

use intel_tex_2::bindings::kernel;
use intel_tex_2::RgbaSurface;

use base::isa::IsaLevel;

/// The C view of a surface; the kernels only read through its pointer.
fn c_surface(surface: &RgbaSurface) -> kernel::rgba_surface {
    kernel::rgba_surface {
        ptr: surface.data.as_ptr() as *mut u8,
        width: surface.width as i32,
        height: surface.height as i32,
        stride: surface.stride as i32,
    }
}

fn check_sizes(surface: &RgbaSurface, blocks: &[u8], block_bytes: usize) {
    let block_count = (surface.width as usize).div_ceil(4) * (surface.height as usize).div_ceil(4);
    assert_eq!(
        blocks.len(),
        block_count * block_bytes,
        "output size of a {}x{} surface",
        surface.width,
        surface.height
    );
    assert!(
        surface.data.len()
            >= (surface.height as usize).saturating_sub(1) * surface.stride as usize + surface.width as usize * 4
    );
}

/// A kernel that compresses a surface's blocks.
type SurfaceKernel = unsafe extern "C" fn(*mut kernel::rgba_surface, *mut u8);
/// A kernel that compresses a surface's blocks with settings (BC7).
type SettingsKernel = unsafe extern "C" fn(*mut kernel::rgba_surface, *mut u8, *mut kernel::bc7_enc_settings);

/// One kernel per level, in `IsaLevel::ALL` order; the last is the crate's dispatch, which
/// picks the CPU's best. Where the per-level symbols are not declared, every level dispatches.
#[cfg(all(target_arch = "x86_64", unix))]
mod kernels {
    use super::per_level::*;
    use super::{kernel, SettingsKernel, SurfaceKernel};

    pub const BC1: [SurfaceKernel; 4] = [
        CompressBlocksBC1_ispc_sse2,
        CompressBlocksBC1_ispc_sse4,
        CompressBlocksBC1_ispc_avx2,
        kernel::CompressBlocksBC1_ispc,
    ];
    pub const BC3: [SurfaceKernel; 4] = [
        CompressBlocksBC3_ispc_sse2,
        CompressBlocksBC3_ispc_sse4,
        CompressBlocksBC3_ispc_avx2,
        kernel::CompressBlocksBC3_ispc,
    ];
    pub const BC7: [SettingsKernel; 4] = [
        CompressBlocksBC7_ispc_sse2,
        CompressBlocksBC7_ispc_sse4,
        CompressBlocksBC7_ispc_avx2,
        kernel::CompressBlocksBC7_ispc,
    ];
}

#[cfg(not(all(target_arch = "x86_64", unix)))]
mod kernels {
    use super::{kernel, SettingsKernel, SurfaceKernel};

    pub const BC1: [SurfaceKernel; 4] = [kernel::CompressBlocksBC1_ispc; 4];
    pub const BC3: [SurfaceKernel; 4] = [kernel::CompressBlocksBC3_ispc; 4];
    pub const BC7: [SettingsKernel; 4] = [kernel::CompressBlocksBC7_ispc; 4];
}

/// The kernel of the process's level: that level's own below AVX-512 (on a CPU with AVX but
/// not AVX2 the SSE4 one, not the crate's AVX choice, so that the output family stays known),
/// the crate's dispatch at AVX-512.
fn at_kernel_level<K: Copy>(kernels: &[K; 4]) -> K {
    kernels[base::isa::kernel_isa() as usize]
}

/// BC1 blocks of `surface` into `blocks` (8 bytes each, row-major).
pub(crate) fn compress_bc1(surface: &RgbaSurface, blocks: &mut [u8]) {
    compress_with(at_kernel_level(&kernels::BC1), surface, blocks, 8);
}

/// BC3 blocks of `surface` into `blocks` (16 bytes each, row-major).
pub(crate) fn compress_bc3(surface: &RgbaSurface, blocks: &mut [u8]) {
    compress_with(at_kernel_level(&kernels::BC3), surface, blocks, 16);
}

fn compress_with(compress: SurfaceKernel, surface: &RgbaSurface, blocks: &mut [u8], block_bytes: usize) {
    check_sizes(surface, blocks, block_bytes);
    let mut c = c_surface(surface);
    // Safety: the sizes were checked; every kernel of a table is the same kernel at one ISA
    // level, and a level's own is only called when the CPU has it (`kernel_isa` ≤ `detected_isa`).
    unsafe { compress(&mut c, blocks.as_mut_ptr()) }
}

/// BC7 blocks of `surface` into `blocks` (16 bytes each, row-major).
pub(crate) fn compress_bc7(settings: &intel_tex_2::bc7::EncodeSettings, surface: &RgbaSurface, blocks: &mut [u8]) {
    check_sizes(surface, blocks, 16);
    let mut c = c_surface(surface);
    let mut settings = kernel::bc7_enc_settings {
        mode_selection: settings.mode_selection,
        refineIterations: settings.refine_iterations.map(|iterations| iterations as i32),
        skip_mode2: settings.skip_mode2,
        fastSkipTreshold_mode1: settings.fast_skip_threshold_mode1 as i32,
        fastSkipTreshold_mode3: settings.fast_skip_threshold_mode3 as i32,
        fastSkipTreshold_mode7: settings.fast_skip_threshold_mode7 as i32,
        mode45_channel0: settings.mode45_channel0 as i32,
        refineIterations_channel: settings.refine_iterations_channel as i32,
        channels: settings.channels,
    };
    // Safety: as in `compress_with`.
    unsafe { at_kernel_level(&kernels::BC7)(&mut c, blocks.as_mut_ptr(), &mut settings) }
}

/// Which of the kernels' outputs this process makes, for cache keys: measured on the corpus
/// (`cargo bench -- isa`), the AVX2 and AVX-512 kernels give the same bytes, and the SSE4 and
/// SSE2 ones others (no fused multiply-add, four lanes).
pub fn output_family() -> &'static str {
    if !cfg!(all(target_arch = "x86_64", unix)) {
        return "ispc-native";
    }
    match base::isa::kernel_isa() {
        IsaLevel::Avx2 | IsaLevel::Avx512 => "ispc-avx2",
        IsaLevel::Sse4 => "ispc-sse4",
        IsaLevel::Portable => "ispc-sse2",
    }
}

/// Each kernel at one level: the symbols ISPC gives the per-target copies it links beside its
/// dispatching entry point (`CompressBlocksBC7_ispc` → `CompressBlocksBC7_ispc_avx2`).
#[cfg(all(target_arch = "x86_64", unix))]
#[allow(non_snake_case)]
mod per_level {
    use intel_tex_2::bindings::kernel::{bc7_enc_settings, rgba_surface};

    extern "C" {
        pub(crate) fn CompressBlocksBC1_ispc_sse2(src: *mut rgba_surface, dst: *mut u8);
        pub(crate) fn CompressBlocksBC1_ispc_sse4(src: *mut rgba_surface, dst: *mut u8);
        pub(crate) fn CompressBlocksBC1_ispc_avx2(src: *mut rgba_surface, dst: *mut u8);
        pub(crate) fn CompressBlocksBC3_ispc_sse2(src: *mut rgba_surface, dst: *mut u8);
        pub(crate) fn CompressBlocksBC3_ispc_sse4(src: *mut rgba_surface, dst: *mut u8);
        pub(crate) fn CompressBlocksBC3_ispc_avx2(src: *mut rgba_surface, dst: *mut u8);
        pub(crate) fn CompressBlocksBC7_ispc_sse2(
            src: *mut rgba_surface,
            dst: *mut u8,
            settings: *mut bc7_enc_settings,
        );
        pub(crate) fn CompressBlocksBC7_ispc_sse4(
            src: *mut rgba_surface,
            dst: *mut u8,
            settings: *mut bc7_enc_settings,
        );
        pub(crate) fn CompressBlocksBC7_ispc_avx2(
            src: *mut rgba_surface,
            dst: *mut u8,
            settings: *mut bc7_enc_settings,
        );
    }
}
