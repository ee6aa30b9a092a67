//! What the emulated devices drive: a muscle (or a test plant) stepped every 1 ms with the
//! pulse the device delivered. The emulators own this narrow interface so that they need
//! no muscle model; the muscle models (sim-muscle's plants) are adapted to it by
//! `sim_muscle::plant::OnDevice` (`sim-muscle stimulator`, `sim-muscle rehastim2`,
//! `test-stimulator`).

/// One stimulation pulse as the device delivered it, in physical units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pulse {
    /// Pulse amplitude in milliamperes.
    pub amplitude_ma: f64,
    /// Pulse (phase) width in microseconds.
    pub width_us: f64,
}

/// A plant advanced in fixed steps of [`Plant::ts`] seconds by an emulated device.
///
/// Sample k covers `[k Ts, (k+1) Ts)`: a pulse passed to `step` fires at `t = k Ts`;
/// `step` advances the plant to `t = (k+1) Ts` and returns the force there, in newtons.
pub trait Plant: Send {
    /// Sample period in seconds (the devices run a 1 ms loop and refuse any other).
    fn ts(&self) -> f64;
    /// Advances one sample, firing `pulse` at its start; returns the force (N) at its end.
    fn step(&mut self, pulse: Option<Pulse>) -> f64;
}

/// A boxed plant is a plant, so a caller can choose the plant at run time.
impl<P: Plant + ?Sized> Plant for Box<P> {
    fn ts(&self) -> f64 {
        (**self).ts()
    }
    fn step(&mut self, pulse: Option<Pulse>) -> f64 {
        (**self).step(pulse)
    }
}
