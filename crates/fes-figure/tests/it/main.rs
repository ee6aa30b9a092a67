//! fes-figure's tests, one binary: the palette is tab10, a time series' strip and panel
//! line up, a figure's backend follows its file's extension.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod backends;
mod palette;
mod panels;
