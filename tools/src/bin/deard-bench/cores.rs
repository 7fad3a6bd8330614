//! Where the bench runs: pinned to one core (`--pin-cpu`), and a busy board (`--hog-cpu`, a
//! process spinning on another core for the whole measurement).
//!
//! Pinning is done first thing in `main`, before any other thread exists: the affinity of a
//! Linux thread is inherited by the threads it creates, so the rayon pool (one thread), the
//! background calibration worker (nice +19 above the frame path) and tract all run on that
//! core. `taskset -c 0 env RAYON_NUM_THREADS=1 deard …` does the same to the daemon.
//!
//! The hog is this program started again as `deard-bench --spin-cpu N`: it pins itself to CPU
//! N and spins until it is killed, which [`Hogs`] does when dropped (the measurement ended, or
//! failed).

use std::process::{Child, Command, Stdio};

/// The first argument that makes this program a CPU hog instead of a bench.
pub const SPIN_FLAG: &str = "--spin-cpu";

/// Pins the calling thread, and every thread it starts later, to `cpu`.
pub fn pin_to(cpu: usize) -> Result<(), String> {
    dear_pipeline::threads::pin_current_thread(cpu).map_err(|e| {
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        format!(
            "cannot pin to CPU {cpu}: {e} (this process may use {cpus} CPUs; `nproc` lists them)"
        )
    })
}

/// `deard-bench --spin-cpu N`: pins itself to CPU `N` and spins until killed.
pub fn spin(arg: Option<String>) -> Result<(), String> {
    let cpu: usize = arg
        .as_deref()
        .ok_or_else(|| format!("{SPIN_FLAG} needs a CPU number"))?
        .parse()
        .map_err(|e| format!("{SPIN_FLAG} {}: {e}", arg.as_deref().unwrap_or("")))?;
    pin_to(cpu)?;
    let mut x = 1u64;
    loop {
        // Integer work the optimiser cannot remove: a core busy at 100 %, as an app's thread.
        for _ in 0..1_000_000 {
            x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
        }
    }
}

/// The hog processes of a busy-board measurement; dropping this kills and reaps them.
#[derive(Debug, Default)]
pub struct Hogs {
    children: Vec<(usize, Child)>,
}

impl Hogs {
    /// Starts one spinning process per CPU in `cpus`.
    pub fn start(cpus: &[usize]) -> Result<Self, String> {
        let exe = std::env::current_exe()
            .map_err(|e| format!("cannot find this program to start the CPU hog: {e}"))?;
        let mut hogs = Hogs::default();
        for &cpu in cpus {
            let child = Command::new(&exe)
                .arg(SPIN_FLAG)
                .arg(cpu.to_string())
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .spawn()
                .map_err(|e| format!("cannot start the CPU hog on CPU {cpu}: {e}"))?;
            hogs.children.push((cpu, child));
        }
        // A hog that cannot pin itself (no such CPU) exits at once with its reason on stderr.
        std::thread::sleep(std::time::Duration::from_millis(200));
        for (cpu, child) in &mut hogs.children {
            if let Ok(Some(status)) = child.try_wait() {
                return Err(format!(
                    "the CPU hog on CPU {cpu} stopped at once ({status})"
                ));
            }
        }
        Ok(hogs)
    }

    /// `"CPU 1 (pid 1234)"`, … for the report.
    pub fn describe(&self) -> String {
        self.children
            .iter()
            .map(|(cpu, child)| format!("CPU {cpu} (pid {})", child.id()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl Drop for Hogs {
    fn drop(&mut self) {
        for (_, child) in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}
