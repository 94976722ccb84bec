//! Intel's ISPC texture compressor (`intel_tex_2`) for BC1, BC3 and BC7, run at the process's
//! kernel instruction-set level (`crate::isa`): the crate's library holds each kernel compiled for
//! SSE2, SSE4, AVX2 and AVX-512 and picks the CPU's best; a lower limit calls that level's kernel
//! by its own symbol.

use intel_tex_2::bindings::kernel;
use intel_tex_2::RgbaSurface;

use crate::isa::IsaLevel;

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
    assert_eq!(blocks.len(), block_count * block_bytes, "output size of a {}x{} surface", surface.width, surface.height);
    assert!(surface.data.len() >= (surface.height as usize).saturating_sub(1) * surface.stride as usize + surface.width as usize * 4);
}

/// BC1 blocks of `surface` into `blocks` (8 bytes each, row-major).
pub fn compress_bc1(surface: &RgbaSurface, blocks: &mut [u8]) {
    check_sizes(surface, blocks, 8);
    let mut c = c_surface(surface);
    let (src, dst) = (&mut c as *mut kernel::rgba_surface, blocks.as_mut_ptr());
    // Safety: the sizes were checked; every symbol is the same kernel at one ISA level, and the
    // level's kernel is only called when the CPU has it (`kernel_isa` ≤ `detected_isa`).
    unsafe {
        match at_level() {
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Portable => per_level::CompressBlocksBC1_ispc_sse2(src, dst),
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Sse4 => per_level::CompressBlocksBC1_ispc_sse4(src, dst),
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Avx2 => per_level::CompressBlocksBC1_ispc_avx2(src, dst),
            _ => kernel::CompressBlocksBC1_ispc(src, dst),
        }
    }
}

/// BC3 blocks of `surface` into `blocks` (16 bytes each, row-major).
pub fn compress_bc3(surface: &RgbaSurface, blocks: &mut [u8]) {
    check_sizes(surface, blocks, 16);
    let mut c = c_surface(surface);
    let (src, dst) = (&mut c as *mut kernel::rgba_surface, blocks.as_mut_ptr());
    // Safety: as in `compress_bc1`.
    unsafe {
        match at_level() {
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Portable => per_level::CompressBlocksBC3_ispc_sse2(src, dst),
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Sse4 => per_level::CompressBlocksBC3_ispc_sse4(src, dst),
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Avx2 => per_level::CompressBlocksBC3_ispc_avx2(src, dst),
            _ => kernel::CompressBlocksBC3_ispc(src, dst),
        }
    }
}

/// BC7 blocks of `surface` into `blocks` (16 bytes each, row-major).
pub fn compress_bc7(settings: &intel_tex_2::bc7::EncodeSettings, surface: &RgbaSurface, blocks: &mut [u8]) {
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
    let (src, dst, settings) = (&mut c as *mut kernel::rgba_surface, blocks.as_mut_ptr(), &mut settings as *mut kernel::bc7_enc_settings);
    // Safety: as in `compress_bc1`.
    unsafe {
        match at_level() {
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Portable => per_level::CompressBlocksBC7_ispc_sse2(src, dst, settings),
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Sse4 => per_level::CompressBlocksBC7_ispc_sse4(src, dst, settings),
            #[cfg(all(target_arch = "x86_64", unix))]
            IsaLevel::Avx2 => per_level::CompressBlocksBC7_ispc_avx2(src, dst, settings),
            _ => kernel::CompressBlocksBC7_ispc(src, dst, settings),
        }
    }
}

/// Which of the kernels' outputs this process makes, for cache keys: measured on the corpus
/// (`cargo bench -- isa`), the AVX2 and AVX-512 kernels give the same bytes, and the SSE4 and
/// SSE2 ones others (no fused multiply-add, four lanes).
pub fn output_family() -> &'static str {
    if !cfg!(all(target_arch = "x86_64", unix)) {
        return "ispc-native";
    }
    match crate::isa::kernel_isa() {
        IsaLevel::Avx2 | IsaLevel::Avx512 => "ispc-avx2",
        IsaLevel::Sse4 => "ispc-sse4",
        IsaLevel::Portable => "ispc-sse2",
    }
}

/// The level to call: below AVX-512, that level's own kernel (on a CPU with AVX but not AVX2
/// the SSE4 one, not the crate's AVX choice, so that the output family stays known); at
/// AVX-512, the crate's dispatch.
fn at_level() -> IsaLevel {
    crate::isa::kernel_isa()
}

/// Each kernel at one level: the symbols ISPC gives the per-target copies it links beside its
/// dispatching entry point (`CompressBlocksBC7_ispc` → `CompressBlocksBC7_ispc_avx2`).
#[cfg(all(target_arch = "x86_64", unix))]
#[allow(non_snake_case)]
mod per_level {
    use intel_tex_2::bindings::kernel::{bc7_enc_settings, rgba_surface};

    extern "C" {
        pub fn CompressBlocksBC1_ispc_sse2(src: *mut rgba_surface, dst: *mut u8);
        pub fn CompressBlocksBC1_ispc_sse4(src: *mut rgba_surface, dst: *mut u8);
        pub fn CompressBlocksBC1_ispc_avx2(src: *mut rgba_surface, dst: *mut u8);
        pub fn CompressBlocksBC3_ispc_sse2(src: *mut rgba_surface, dst: *mut u8);
        pub fn CompressBlocksBC3_ispc_sse4(src: *mut rgba_surface, dst: *mut u8);
        pub fn CompressBlocksBC3_ispc_avx2(src: *mut rgba_surface, dst: *mut u8);
        pub fn CompressBlocksBC7_ispc_sse2(src: *mut rgba_surface, dst: *mut u8, settings: *mut bc7_enc_settings);
        pub fn CompressBlocksBC7_ispc_sse4(src: *mut rgba_surface, dst: *mut u8, settings: *mut bc7_enc_settings);
        pub fn CompressBlocksBC7_ispc_avx2(src: *mut rgba_surface, dst: *mut u8, settings: *mut bc7_enc_settings);
    }
}
