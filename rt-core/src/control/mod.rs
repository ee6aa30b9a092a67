//! The Local Controller Network and the pattern generator (thesis ch. 3, 6.5, App. C).
//!
//! - [`poles`]: desired closed-loop poles from rise time and damping (6.5.3).
//! - [`design`]: pole placement with integral action and the state estimator, per local
//!   model, in the delta domain (C.2.1-C.2.3).
//! - [`shaper`]: the pulse shaper (6.5.2, eq. 6.7-6.8).
//!
//! See `docs/control.md` for the equations, the design procedure and the conventions.

pub mod design;
pub mod poles;
pub mod shaper;
