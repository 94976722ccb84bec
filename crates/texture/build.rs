//! Build script: links the C++ runtime that the ISPC texture compressor kernels of `intel_tex_2`
//! (compiled C++) need.

fn main() {
    println!("cargo:rustc-link-lib=stdc++");
    println!("cargo:rerun-if-changed=build.rs");
}
