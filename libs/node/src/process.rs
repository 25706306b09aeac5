//! How a Troupe process lives and dies: stopped by SIGTERM or SIGINT (also
//! as a container's PID 1, where a signal with no handler is ignored), and,
//! under `troupe launch`, never outliving its launcher.
//!
//! Drivers get this from [`run`](crate::run); the long-running clients (the
//! bridge, a passthrough, the view) and the tools take it from here.

use crate::{Mode, NodeError, ZenohArgs};

/// Set by `troupe launch` on every child: the launcher's process id.
pub const SUPERVISOR_ENV: &str = "TROUPE_SUPERVISOR_PID";

/// What can keep a process from starting its life as a Troupe process.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The kernel refused to tie this process to its launcher.
    #[error("asking to be stopped with the launcher: {0}")]
    Deathsig(nix::Error),
    /// The launcher died before this process could tie itself to it.
    #[error("the launcher (pid {0}) is gone")]
    LauncherGone(String),
    /// The Tokio runtime could not start.
    #[error("starting the runtime: {0}")]
    Runtime(std::io::Error),
    /// The signal handlers could not be installed.
    #[error("catching SIGTERM and SIGINT: {0}")]
    Signals(std::io::Error),
    /// The session could not be opened.
    #[error(transparent)]
    Node(#[from] NodeError),
}

/// Under `troupe launch`: die with the launcher, never outlive it.
///
/// # Errors
///
/// The kernel refuses the request, or the launcher is already gone.
pub fn supervised() -> Result<(), ProcessError> {
    let Ok(ppid) = std::env::var(SUPERVISOR_ENV) else {
        return Ok(());
    };
    nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGTERM)
        .map_err(ProcessError::Deathsig)?;
    // The launcher may have died before the request took effect.
    if nix::unistd::getppid().as_raw().to_string() != ppid {
        return Err(ProcessError::LauncherGone(ppid));
    }
    Ok(())
}

/// SIGTERM and SIGINT, caught from the moment this is made: as a
/// container's PID 1 a signal with no handler is ignored, not fatal.
pub struct StopSignals {
    term: tokio::signal::unix::Signal,
    int: tokio::signal::unix::Signal,
}

impl StopSignals {
    /// Installs the handlers (needs a Tokio runtime).
    ///
    /// # Errors
    ///
    /// The handlers cannot be installed.
    pub fn new() -> std::io::Result<StopSignals> {
        use tokio::signal::unix::{signal, SignalKind};
        Ok(StopSignals {
            term: signal(SignalKind::terminate())?,
            int: signal(SignalKind::interrupt())?,
        })
    }

    /// The next SIGTERM or SIGINT (Ctrl-C), logged.
    pub async fn recv(&mut self) {
        let which = self.next().await;
        tracing::info!("{which}");
    }

    /// The next SIGTERM or SIGINT: its name.
    async fn next(&mut self) -> &'static str {
        tokio::select! {
            _ = self.term.recv() => "SIGTERM",
            _ = self.int.recv() => "SIGINT",
        }
    }

    /// The session `open` makes, or `None` when a signal comes first (with
    /// `--reconnect` an open waits for its router, and PID 1 must still stop).
    ///
    /// # Errors
    ///
    /// The session cannot be opened.
    pub async fn unless_stopped(
        &mut self,
        open: impl std::future::Future<Output = crate::Result<zenoh::Session>>,
    ) -> crate::Result<Option<zenoh::Session>> {
        tokio::select! {
            s = open => s.map(Some),
            () = self.recv() => {
                tracing::info!("stopped before the router answered");
                Ok(None)
            }
        }
    }
}

/// A runtime, the stop signals caught on it, and a session.
pub type SessionRuntime = (tokio::runtime::Runtime, StopSignals, zenoh::Session);

/// How a long-running tool (the bridge, the view, a passthrough) starts: a
/// runtime of `threads` workers, SIGTERM and SIGINT caught before the
/// session opens (with `--reconnect` the open waits for its router, and a
/// container's PID 1 must still stop), then the session, joining as `mode`
/// unless `--mode` or the config says otherwise (a peer takes data from its
/// publishers directly, not through the router); `None` when a signal came
/// first.
///
/// # Errors
///
/// The runtime, the handlers or the session cannot start.
pub fn session_runtime(
    z: &ZenohArgs,
    threads: usize,
    mode: Mode,
) -> Result<Option<SessionRuntime>, ProcessError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(threads)
        .enable_all()
        .build()
        .map_err(ProcessError::Runtime)?;
    let mut signals = rt
        .block_on(async { StopSignals::new() })
        .map_err(ProcessError::Signals)?;
    let session = rt.block_on(signals.unless_stopped(z.open_in_background(mode)))?;
    Ok(session.map(|s| (rt, signals, s)))
}

/// Calls `then` on a thread of its own at the first SIGINT or SIGTERM
/// (logged). The handlers are installed when this returns: a signal sent
/// from then on (say, by a script that saw the process's first line) stops
/// the process, where one sent before a handler was up would kill it.
///
/// # Errors
///
/// The thread, its runtime or the handlers cannot start.
pub fn on_stop_signal(then: impl FnOnce() + Send + 'static) -> std::io::Result<()> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            let rt = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(rt) => rt,
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            rt.block_on(async {
                match StopSignals::new() {
                    Ok(mut signals) => {
                        let _ = ready_tx.send(Ok(()));
                        signals.recv().await;
                        then();
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                    }
                }
            });
        })?;
    ready_rx
        .recv()
        .unwrap_or_else(|_| Err(std::io::Error::other("the signal thread died")))
}

/// A flag raised at the first SIGINT or SIGTERM (see [`on_stop_signal`]),
/// for a loop that checks it between rounds.
///
/// # Errors
///
/// As [`on_stop_signal`].
pub fn stop_flag() -> std::io::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let flag = std::sync::Arc::new(AtomicBool::new(false));
    let raised = flag.clone();
    on_stop_signal(move || raised.store(true, Ordering::Relaxed))?;
    Ok(flag)
}

/// A channel that receives once at the first SIGINT or SIGTERM (see
/// [`on_stop_signal`]), for a thread that waits on it.
///
/// # Errors
///
/// As [`on_stop_signal`].
pub fn stop_receiver() -> std::io::Result<std::sync::mpsc::Receiver<()>> {
    let (tx, rx) = std::sync::mpsc::channel();
    on_stop_signal(move || {
        let _ = tx.send(());
    })?;
    Ok(rx)
}
