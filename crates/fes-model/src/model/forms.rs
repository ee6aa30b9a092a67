//! Two equivalent ways to run a network with input delay d (thesis 2.2.2).
//!
//! - [`ThesisForm`]: a delay line on the input, as in eq. 2.14: the local models (and, in the
//!   delayed class, the scheduler) are driven by u\[k-d\]; its state is the thesis's x\[k\]. Used
//!   for simulation and identification, wherever a plant is simulated, and by the thesis's
//!   delayed loop on the undelayed class.
//! - [`AdvancedForm`]: the core driven by u\[k\] directly, followed by a ring buffer of the last
//!   d core outputs. Its state is z\[k\] = x\[k+d\], known exactly at time k because every input
//!   that reaches it is already decided. The pattern generator's controller acts on z. It
//!   exists only where the core can run ahead ([`Network::can_run_ahead`]): in the undelayed
//!   class (eq. 5.2) phi at k+d depends on the pulses of k..k+d-1.
//!
//! Both start "from rest" (see [`Network::rest_state`]); the advanced form's ring holds the
//! outputs of the first d thesis-form steps (whose delayed input is zero), computed by running
//! the core d steps with zero input, so the two give the same output sequence (a test checks
//! it for random pulse trains). Neither allocates, locks, or panics in `step`.

use super::network::{CoreState, MAX_DELAY, Network, NetworkError};
use super::validity::Activation;
use crate::num::Scalar;

/// A fixed-capacity FIFO of exactly `len` samples (0 <= len <= [`MAX_DELAY`]): pushing one
/// value returns the one pushed `len` pushes earlier.
#[derive(Debug, Clone, Copy)]
pub struct DelayLine<T: Copy> {
    buf: [T; MAX_DELAY],
    len: usize,
    head: usize,
}

impl<T: Copy> DelayLine<T> {
    /// A delay line of `len` samples, pre-filled with `fill`; `None` if len > MAX_DELAY.
    pub fn new(len: usize, fill: T) -> Option<Self> {
        (len <= MAX_DELAY).then_some(Self {
            buf: [fill; MAX_DELAY],
            len,
            head: 0,
        })
    }

    /// Number of samples of delay.
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for a zero-length (pass-through) line.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Pushes `x`, returns the value pushed `len` calls earlier (or `x` itself if len = 0).
    #[inline(always)]
    pub fn push(&mut self, x: T) -> T {
        if self.len == 0 {
            return x;
        }
        let out = self.buf[self.head];
        self.buf[self.head] = x;
        self.head += 1;
        if self.head == self.len {
            self.head = 0;
        }
        out
    }

    /// The value that the next `push` will return.
    #[inline]
    pub fn front(&self) -> Option<T> {
        (self.len > 0).then(|| self.buf[self.head])
    }

    /// The i-th oldest stored value (0 = next out), i < len.
    #[inline]
    pub fn get(&self, i: usize) -> Option<T> {
        (i < self.len).then(|| {
            let j = self.head + i;
            self.buf[if j >= self.len { j - self.len } else { j }]
        })
    }
}

/// The network in the thesis's form: delay line on the input, state x\[k\].
#[derive(Debug, Clone)]
pub struct ThesisForm<S: Scalar = f64> {
    net: Network<S>,
    state: CoreState<S>,
    input_delay: DelayLine<f64>,
}

impl<S: Scalar> ThesisForm<S> {
    /// Starts at rest (no pulses before k = 0).
    pub fn new(net: Network<S>) -> Result<Self, NetworkError> {
        let state = net.rest_state()?;
        let input_delay =
            DelayLine::new(net.delay(), 0.0).ok_or(NetworkError::Delay(net.delay()))?;
        Ok(Self {
            net,
            state,
            input_delay,
        })
    }

    /// One sample: pulse input u\[k\] in, model output y\[k\] out.
    #[inline]
    pub fn step(&mut self, u: f64) -> S {
        let act = self.net.activation(&self.state);
        self.step_with_activation(&act, u)
    }

    /// [`Self::step`] reusing an activation already evaluated at the state's phi.
    #[inline]
    pub fn step_with_activation(&mut self, act: &Activation<S>, u: f64) -> S {
        let v = self.input_delay.push(u);
        self.net.step_inputs(&mut self.state, act, v, u)
    }

    /// The core state before the next step (x\[k\], prefilter state, phi\[k\]).
    #[inline]
    pub fn state(&self) -> &CoreState<S> {
        &self.state
    }

    /// The network.
    #[inline]
    pub fn network(&self) -> &Network<S> {
        &self.net
    }
}

/// Outputs of one [`AdvancedForm::step`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdvancedStep<S = f64> {
    /// The model output now, y\[k\] (identical to the thesis form's).
    pub y: S,
    /// The core output y\[k + d\]: the output the model will show d samples from now.
    pub y_ahead: S,
}

/// The network in the advanced form: core state z\[k\] = x\[k+d\] plus a ring of d outputs.
#[derive(Debug, Clone)]
pub struct AdvancedForm<S: Scalar = f64> {
    net: Network<S>,
    state: CoreState<S>,
    outputs: DelayLine<S>,
}

impl<S: Scalar> AdvancedForm<S> {
    /// Starts at rest: the core runs d steps with zero input, filling the output ring.
    /// Refused for a network that cannot run ahead ([`Network::can_run_ahead`]).
    pub fn new(net: Network<S>) -> Result<Self, NetworkError> {
        if !net.can_run_ahead() {
            return Err(NetworkError::CannotRunAhead { delay: net.delay() });
        }
        let mut state = net.rest_state()?;
        let mut outputs =
            DelayLine::new(net.delay(), S::zero()).ok_or(NetworkError::Delay(net.delay()))?;
        for _ in 0..net.delay() {
            let y = net.step(&mut state, 0.0);
            outputs.push(y);
        }
        Ok(Self {
            net,
            state,
            outputs,
        })
    }

    /// The core state z\[k\] = x\[k+d\] with its scheduling value (before the next step).
    #[inline]
    pub fn state(&self) -> &CoreState<S> {
        &self.state
    }

    /// The scheduling value the core will use for the pulse decided now.
    #[inline]
    pub fn phi(&self) -> S {
        self.state.phi
    }

    /// The activation of the validity functions at [`Self::phi`].
    #[inline]
    pub fn activation(&self) -> Activation<S> {
        self.net.activation(&self.state)
    }

    /// One sample: pulse u\[k\] decided now.
    #[inline]
    pub fn step(&mut self, u: f64) -> AdvancedStep<S> {
        let act = self.net.activation(&self.state);
        self.step_with_activation(&act, u)
    }

    /// [`Self::step`] reusing an activation already evaluated at [`Self::phi`].
    #[inline]
    pub fn step_with_activation(&mut self, act: &Activation<S>, u: f64) -> AdvancedStep<S> {
        let y_ahead = self.net.step_with_activation(&mut self.state, act, u);
        let y = self.outputs.push(y_ahead);
        AdvancedStep { y, y_ahead }
    }

    /// The model outputs already determined for the next d samples, oldest first: entry i is
    /// y\[k + i\] before the step at time k.
    #[inline]
    pub fn pending_output(&self, i: usize) -> Option<S> {
        self.outputs.get(i)
    }

    /// The network.
    #[inline]
    pub fn network(&self) -> &Network<S> {
        &self.net
    }
}
