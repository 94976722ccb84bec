//! Long work that stops when asked: the check a pure kernel asks between its units (AO points and
//! rays, an impostor's render batches, tasks of encoded blocks), and what it gives when it stops.
//! A leaf, so that every library can take it; the driver passes its cancellation check
//! (`db::stoppable`), tests and benches pass [`never`].

/// Asked between units of long work: `true` stops the work with [`Stopped`].
pub type ShouldStop<'a> = &'a (dyn Fn() -> bool + Sync);

/// Long work stopped because [`ShouldStop`] said so; what it made is thrown away.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stopped;

/// A [`ShouldStop`] that never stops.
pub fn never() -> bool {
    false
}
