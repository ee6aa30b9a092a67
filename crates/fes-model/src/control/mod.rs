//! The Local Controller Network and the pattern generator (thesis ch. 3, 6.5, App. C).
//!
//! - [`poles`]: desired closed-loop poles from rise time and damping (6.5.3).
//! - [`design`]: pole placement with integral action and the state estimator, per local
//!   model, in the delta domain (C.2.1-C.2.3).
//! - [`io_design`]: input-output pole placement with integral action for ARX local models
//!   and its LCN (C.1; App. E.4.7).
//! - [`lcn_design`]: the design of every unit of an LCN from an LMN (3.3, 6.5.3).
//! - [`lcn`]: the Local Controller Network at run time: interpolated gains, control law,
//!   anti-windup (3.3, C.2.3).
//! - [`shaper`]: the pulse shaper (6.5.2, eq. 6.7-6.8).
//! - [`estimator`]: the state estimator of the measured-force mode (C.2.2, Fig. 6.6(a)).
//! - [`pattern_generator`]: the 1 ms tick of Fig. 6.8 in the model's advanced form.
//! - [`mod@file`]: the controller file `fes-lcn/1`.
//!
//! See `docs/control.md` for the equations, the design procedure and the conventions.

pub mod design;
pub mod estimator;
pub mod file;
pub mod io_design;
pub mod lcn;
pub mod lcn_design;
pub mod pattern_generator;
pub mod planner;
pub mod poles;
pub mod preview;
pub mod shaper;
