//! What the workspace's tests share, written once: where the workspace's binaries and sample
//! data are ([`paths`]), a unique service name per test and waiting for a child to exit
//! ([`process`]), a running `deard` with waits on its log lines and counters ([`daemon`]), and
//! the capture directories tests write ([`capture`]: copies of `samples/demo` with unreadable
//! frames; [`scene`]: an analytic scene through the real capture writer).
//!
//! Every wait here has a deadline and panics with what it waited for and the process's log;
//! none sleeps a fixed time and assumes a state was reached.
//!
//! It starts the binaries of `deard`, `dear` and the test clients; it links none of their
//! crates, so any crate can take it as a dev-dependency.

pub mod capture;
pub mod daemon;
pub mod paths;
pub mod process;
pub mod scene;
