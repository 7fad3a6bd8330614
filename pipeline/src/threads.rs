//! The frame path's threads: rayon's global pool, optionally with each thread pinned to a CPU
//! of its own.
//!
//! Why pinning is offered: on the 2-core development machine, `deard-bench` at 640×480 with
//! frames back to back ran a median of 16.1–16.6 ms with a p95 of 31–32 when the scheduler
//! placed the pool's two threads, and 16.1–17.5 / 20.0–20.8 ms with each pinned to one CPU
//! (three alternating pairs). The slow frames came in runs of 3–6 in which every stage took
//! twice its time: the scheduler had put both threads on one CPU for a while (a CPU hog or a
//! memory-bandwidth hog on the other core did not do that to one pinned thread, and the
//! measurement off the frame path was not the cause: the runs came with it off). Why it is not
//! the default: a pinned thread cannot move away from a CPU that another process keeps busy,
//! and the frame waits for it (the same bench with a spinning process on CPU 1: median 72 ms
//! pinned, 34 ms not); at 30 fps offered, when the frame path waits for each frame, it changed
//! nothing measurable. Pin only on CPUs the daemon has
//! to itself (systemd's `CPUAffinity=`, `taskset`, `isolcpus`); on a board whose apps share
//! every core, run it on one (docs/performance.md).

use std::io;

/// Why the pinned pool could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PinThreadsError {
    /// The CPUs this process may run on could not be read.
    #[error("cannot read the CPUs this process may run on: {0}")]
    Affinity(#[source] io::Error),
    /// More threads asked for than CPUs to pin them to.
    #[error(
        "{threads} frame-path threads (RAYON_NUM_THREADS) cannot be pinned to {cpus} CPUs \
         (this process may run on CPUs {list:?}); ask for at most {cpus} threads or allow more CPUs"
    )]
    TooManyThreads {
        threads: usize,
        cpus: usize,
        list: Vec<usize>,
    },
    /// `RAYON_NUM_THREADS` is not a number.
    #[error("RAYON_NUM_THREADS = {0:?} is not a number of threads")]
    ThreadCount(String),
    /// A thread could not be pinned (the CPU went offline, or a seccomp filter refused).
    #[error("cannot pin frame-path thread {index} to CPU {cpu}: {source}")]
    Pin {
        index: usize,
        cpu: usize,
        #[source]
        source: io::Error,
    },
    /// rayon's global pool exists already, or its threads could not be spawned.
    #[error("cannot make the frame path's thread pool: {0}")]
    Pool(#[from] rayon::ThreadPoolBuildError),
}

/// The CPUs this process may run on (its affinity mask), in increasing order.
///
/// # Errors
/// When the mask cannot be read (always, outside Linux).
pub fn allowed_cpus() -> io::Result<Vec<usize>> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: a zeroed cpu_set_t is the empty set; sched_getaffinity fills it for the
        // calling thread (pid 0) given its size; CPU_ISSET reads indices below CPU_SETSIZE.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
                return Err(io::Error::last_os_error());
            }
            Ok((0..libc::CPU_SETSIZE as usize)
                .filter(|&cpu| libc::CPU_ISSET(cpu, &set))
                .collect())
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "CPU affinity is only read on Linux",
        ))
    }
}

/// Pins the calling thread, and the threads it starts afterwards, to `cpu`.
///
/// # Errors
/// When `cpu` is beyond the CPU set, not allowed to this process, or outside Linux.
pub fn pin_current_thread(cpu: usize) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("CPU {cpu} is beyond the CPU set"),
            ));
        }
        // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET with an index below CPU_SETSIZE
        // (checked above); sched_setaffinity on the calling thread (pid 0) with its size.
        let r = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if r != 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = cpu;
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "threads are only pinned on Linux",
        ))
    }
}

/// The number of frame-path threads: `RAYON_NUM_THREADS` when set and not 0 (as rayon reads
/// it), else one per allowed CPU.
fn thread_count(cpus: usize) -> Result<usize, PinThreadsError> {
    match std::env::var("RAYON_NUM_THREADS") {
        Ok(text) => match text.trim().parse::<usize>() {
            Ok(0) => Ok(cpus),
            Ok(n) => Ok(n),
            Err(_) => Err(PinThreadsError::ThreadCount(text)),
        },
        Err(_) => Ok(cpus),
    }
}

/// A pool of `threads` threads (`None`: `thread_count`'s), thread `i` pinned to the `i`-th
/// allowed CPU, and those CPUs. The pins are made as the threads start and checked by
/// [`check_pins`].
///
/// # Errors
/// When the affinity mask cannot be read or holds fewer CPUs than threads.
pub fn pinned_pool_builder(
    threads: Option<usize>,
) -> Result<(rayon::ThreadPoolBuilder, Vec<usize>), PinThreadsError> {
    let allowed = allowed_cpus().map_err(PinThreadsError::Affinity)?;
    let threads = match threads {
        Some(n) => n.max(1),
        None => thread_count(allowed.len())?.max(1),
    };
    if threads > allowed.len() {
        return Err(PinThreadsError::TooManyThreads {
            threads,
            cpus: allowed.len(),
            list: allowed,
        });
    }
    let cpus: Vec<usize> = allowed[..threads].to_vec();
    let pins = cpus.clone();
    let builder = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        // A failure leaves the thread unpinned; `check_pins` finds it and says why.
        .start_handler(move |index| {
            let _ = pin_current_thread(pins[index]);
        });
    Ok((builder, cpus))
}

/// Checks that every thread of the current pool (the global one outside `install`) runs on
/// exactly its CPU of `cpus`.
///
/// # Errors
/// [`PinThreadsError::Pin`] for the first thread that does not.
pub fn check_pins(cpus: &[usize]) -> Result<(), PinThreadsError> {
    let seen = rayon::broadcast(|context| (context.index(), allowed_cpus()));
    for (index, mask) in seen {
        let cpu = cpus[index];
        match mask {
            Ok(mask) if mask == [cpu] => {}
            Ok(mask) => {
                return Err(PinThreadsError::Pin {
                    index,
                    cpu,
                    source: io::Error::other(format!("the thread runs on CPUs {mask:?}")),
                })
            }
            Err(source) => return Err(PinThreadsError::Pin { index, cpu, source }),
        }
    }
    Ok(())
}

/// Makes rayon's global pool, where the frame path's parallel loops run, with each thread
/// pinned to a CPU of its own (see the module docs for when that pays), and returns those
/// CPUs. Call it before anything uses rayon: the global pool is made once.
///
/// # Errors
/// See [`pinned_pool_builder`]; also when the global pool exists already or a pin did not
/// take.
pub fn pin_global_pool() -> Result<Vec<usize>, PinThreadsError> {
    let (builder, cpus) = pinned_pool_builder(None)?;
    builder.build_global()?;
    check_pins(&cpus)?;
    Ok(cpus)
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn each_thread_of_a_pinned_pool_runs_on_its_own_cpu() {
        let allowed = allowed_cpus().unwrap();
        assert!(!allowed.is_empty());
        let threads = allowed.len().min(2);
        let (builder, cpus) = pinned_pool_builder(Some(threads)).unwrap();
        assert_eq!(cpus, allowed[..threads]);
        let pool = builder.build().unwrap();
        pool.install(|| check_pins(&cpus)).unwrap();
        let masks = pool.broadcast(|_| allowed_cpus().unwrap());
        for (index, mask) in masks.iter().enumerate() {
            assert_eq!(mask, &[cpus[index]], "thread {index}");
        }
        // The thread that made the pool keeps its own mask.
        assert_eq!(allowed_cpus().unwrap(), allowed);
    }

    #[test]
    fn more_threads_than_cpus_is_refused_naming_both() {
        let allowed = allowed_cpus().unwrap();
        let error = pinned_pool_builder(Some(allowed.len() + 1)).unwrap_err();
        let message = error.to_string();
        assert!(
            matches!(error, PinThreadsError::TooManyThreads { threads, cpus, .. }
                if threads == allowed.len() + 1 && cpus == allowed.len()),
            "{message}"
        );
        assert!(message.contains("RAYON_NUM_THREADS"), "{message}");
    }

    #[test]
    fn a_pool_pinned_elsewhere_fails_the_check() {
        // A pool of unpinned threads: their mask is the whole allowed set.
        let allowed = allowed_cpus().unwrap();
        if allowed.len() < 2 {
            return; // one CPU: an unpinned thread is on exactly it
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let error = pool.install(|| check_pins(&allowed[..1])).unwrap_err();
        assert!(
            matches!(error, PinThreadsError::Pin { index: 0, .. }),
            "{error}"
        );
    }
}
