//! The commands of `hopper-link`, one module per command or per group of
//! related commands; `main` parses the command line and dispatches here.

pub(crate) mod arm;
pub(crate) mod calibrate;
pub(crate) mod common;
pub(crate) mod dump;
pub(crate) mod flood;
pub(crate) mod params;
pub(crate) mod record;
pub(crate) mod record_planar;
pub(crate) mod robot;
pub(crate) mod save;
pub(crate) mod silence;
pub(crate) mod sim;
pub(crate) mod status;
pub(crate) mod stream;
pub(crate) mod ui;
pub(crate) mod wait;
pub(crate) mod watch;
