//! `study serve`: a study run in participants' browsers.
//!
//! The protocol engine and the session recorder stay on the server, exactly as the study
//! window uses them ([`lab::session::Recorder`], [`lab::source::StimulusSource`]): the page
//! asks for the next trial, downloads its two clips as joint positions, plays them, and posts
//! the answer; the answer is appended to the session's `trials.csv` and fsynced before the
//! server acknowledges it. No rule of any protocol runs in the browser.
//!
//! - [`ServeOptions`], [`serve`] (blocking, until SIGINT/SIGTERM) and [`start`] (in-process,
//!   for tests and the load benchmark).
//! - Participants ([`participants`]): ids from the crowd platform's URL (Prolific, MTurk) or
//!   generated, one session each, an unguessable token (32 bytes from the OS) whose SHA-256
//!   is appended to `participants.csv` and fsynced before the participant gets the link.
//! - Sessions ([`app`]): opened on first use with `resume`, so a server killed at any point
//!   continues every session as `study run --resume` does; a repeated answer to the same
//!   trial index is acknowledged once and logged once.
//! - Stimuli ([`clipdata`]): decoded joint positions of the pending trial's two clips, by slot;
//!   the server resolves the manifest id, so no request names a path (or, in a blind design,
//!   which slot holds the reference).
//! - Limits ([`limits`]): request body size, requests per second per participant and joins
//!   per second, the time a client may take to send a request's head and its body, and
//!   connections per client address; the experimenter's dashboard needs the token given on
//!   the command line.
//!
//! The page itself (`web/page/`, three.js built by `scripts/build-page`) is read from
//! [`ServeOptions::page`] at start-up. Running behind a TLS reverse proxy: `docs/serve.md`.

pub mod app;
pub mod client;
pub mod clipdata;
pub mod database;
mod http;
pub mod limits;
pub mod nginx;
pub mod participants;
mod staging;
pub mod timing;

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};

pub use app::App;
pub use limits::Limits;

/// Why the server could not start or stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WebError {
    /// The study, its stimuli or its results folder.
    #[error(transparent)]
    Lab(#[from] lab::LabError),
    /// A file or socket.
    #[error("{what}: {cause}")]
    Io {
        /// What was being done.
        what: String,
        /// The OS error.
        cause: std::io::Error,
    },
    /// A request that cannot be carried out as asked, with the reason.
    #[error("{0}")]
    Refused(String),
}

impl From<results::ResultsError> for WebError {
    fn from(e: results::ResultsError) -> WebError {
        WebError::Lab(e.into())
    }
}

/// The crate's result type.
pub type Result<T, E = WebError> = std::result::Result<T, E>;

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> WebError {
    let what = what.into();
    move |cause| WebError::Io { what, cause }
}

/// What `study serve` runs.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The study file.
    pub study: PathBuf,
    /// Where the sessions go: a results folder (created on first use; later runs continue
    /// its sessions), or a database run that any number of servers share.
    pub results: lab::results_dir::Destination,
    /// Most connections to the database this server opens at once (with a database).
    pub connections: usize,
    /// Address to listen on (`127.0.0.1:8080` unless told otherwise).
    pub bind: SocketAddr,
    /// The built page (`target/page`, made by `scripts/build-page`).
    pub page: PathBuf,
    /// Token of the experimenter's dashboard; `None`: no dashboard.
    pub dashboard_token: Option<String>,
    /// Request limits.
    pub limits: Limits,
}

/// A running server (from [`start`]).
pub struct Server {
    /// The address it listens on.
    pub addr: SocketAddr,
    app: Arc<App>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<std::io::Result<()>>,
}

impl Server {
    /// The shared state (sessions, participants).
    pub fn app(&self) -> &Arc<App> {
        &self.app
    }

    /// Stops accepting requests, lets those in flight finish, and marks every open session
    /// interrupted (resumable).
    ///
    /// # Errors
    /// The listener failed, or a manifest could not be written.
    pub async fn stop(mut self) -> Result<()> {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        match self.task.await {
            Ok(r) => r.map_err(io("serving"))?,
            Err(e) => return Err(WebError::Refused(format!("the server task failed: {e}"))),
        }
        // The state is let go on a blocking thread too: a database's synchronous clients block
        // on a runtime of their own when they close, which panics on an async worker.
        let app = self.app;
        tokio::task::spawn_blocking(move || {
            let interrupted = app.interrupt_all();
            drop(app);
            interrupted
        })
        .await
        .map_err(|e| WebError::Refused(format!("the server task failed: {e}")))?
    }
}

/// Loads the study, checks every stimulus, opens the results directory and listens on
/// `options.bind` (port 0: any free port, see [`Server::addr`]).
///
/// # Errors
/// A bad study file, a stimulus problem, a results folder of another study, a missing page,
/// or an address that cannot be bound.
pub async fn start(options: ServeOptions) -> Result<Server> {
    let opts = options.clone();
    let app = tokio::task::spawn_blocking(move || App::open(&opts))
        .await
        .map_err(|e| WebError::Refused(format!("loading the study failed: {e}")))??;
    let app = Arc::new(app);
    let listener = tokio::net::TcpListener::bind(options.bind)
        .await
        .map_err(io(format!("listening on {}", options.bind)))?;
    let addr = listener.local_addr().map_err(io("listening"))?;
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let router = http::router(Arc::clone(&app));
    let task = tokio::spawn(accept(listener, router, options.limits, rx));
    Ok(Server {
        addr,
        app,
        shutdown: Some(tx),
        task,
    })
}

/// Open connections per client address.
type Open = Arc<Mutex<HashMap<IpAddr, usize>>>;

/// A connection counted against its address until it is dropped.
struct Counted {
    open: Open,
    ip: IpAddr,
}

impl Counted {
    /// Counts a connection from `ip`, unless `cap` are open from it already.
    fn new(open: &Open, ip: IpAddr, cap: usize) -> Option<Counted> {
        let mut m = open.lock().unwrap_or_else(PoisonError::into_inner);
        let n = m.entry(ip).or_insert(0);
        if *n >= cap {
            return None;
        }
        *n += 1;
        Some(Counted {
            open: Arc::clone(open),
            ip,
        })
    }
}

impl Drop for Counted {
    fn drop(&mut self) {
        let mut m = self.open.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(n) = m.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                m.remove(&self.ip);
            }
        }
    }
}

/// Accepts connections until `stop`, then lets the requests in flight finish. Each
/// connection is HTTP/1.1 with a header read timeout (`limits.header_timeout`, on hyper's
/// timer: a client that has not sent a whole request head in time is disconnected, an idle
/// kept-alive connection too); a client address with `limits.max_connections_per_address`
/// open has its next connection closed at once.
async fn accept(
    listener: tokio::net::TcpListener,
    router: axum::Router,
    limits: Limits,
    stop: tokio::sync::oneshot::Receiver<()>,
) -> std::io::Result<()> {
    let open: Open = Arc::default();
    // Told to every connection when the server stops; its receivers all dropped once the
    // last connection has ended.
    let (close_tx, close_rx) = tokio::sync::watch::channel(());
    let mut stop = std::pin::pin!(stop);
    loop {
        let accepted = tokio::select! {
            _ = &mut stop => break,
            r = listener.accept() => r,
        };
        // Out of file descriptors, or a connection reset before it was taken: the backlog
        // waits a moment rather than spinning.
        let Ok((stream, peer)) = accepted else {
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
            continue;
        };
        let Some(counted) = Counted::new(&open, peer.ip(), limits.max_connections_per_address)
        else {
            drop(stream);
            continue;
        };
        let service = hyper_util::service::TowerToHyperService::new(router.clone());
        let mut closing = close_rx.clone();
        tokio::spawn(async move {
            let mut builder = hyper::server::conn::http1::Builder::new();
            builder
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(limits.header_timeout);
            let io = hyper_util::rt::TokioIo::new(stream);
            let mut conn = std::pin::pin!(builder.serve_connection(io, service));
            let mut shutting = false;
            loop {
                tokio::select! {
                    _ = conn.as_mut() => break,
                    r = closing.changed(), if !shutting => {
                        let _ = r;
                        shutting = true;
                        conn.as_mut().graceful_shutdown();
                    }
                }
            }
            drop(counted);
            drop(closing);
        });
    }
    drop(listener);
    drop(close_rx);
    let _ = close_tx.send(());
    close_tx.closed().await;
    Ok(())
}

/// Runs the server until SIGINT or SIGTERM, then marks the open sessions interrupted.
/// `ready` is told the address once it listens.
///
/// # Errors
/// As [`start`]; a runtime that cannot be built.
pub fn serve(options: ServeOptions, ready: impl FnOnce(&App, SocketAddr)) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(io("starting the async runtime"))?;
    runtime.block_on(async move {
        let server = start(options).await?;
        ready(&server.app, server.addr);
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .map_err(io("installing the SIGTERM handler"))?;
        tokio::select! {
            r = tokio::signal::ctrl_c() => r.map_err(io("waiting for SIGINT"))?,
            _ = term.recv() => {}
        }
        server.stop().await
    })
}
