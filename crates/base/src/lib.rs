//! The leaves every crate of cirrus takes: how a problem with an input is reported (the file and,
//! where the format has them, the line and column), lexical path resolution, the check long work
//! asks before it goes on, and the instruction-set level the CPU kernels run at.

pub mod diagnostic;
pub mod isa;
pub mod paths;
pub mod stop;
