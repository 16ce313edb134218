//! `study serve`: a study run in participants' browsers (the `web` crate does the work).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Args;
use lab::StudyFile;

/// Arguments of `study serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// The study file.
    pub study: PathBuf,
    /// Results directory (default: `results-<name>` beside the study file); a later run
    /// continues its sessions.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Address and port to listen on. The default serves this machine only; put a TLS
    /// reverse proxy in front to serve participants (docs/serve.md).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,
    /// The built study page (`scripts/build-page`; default: `page` beside the folder of the
    /// `study` binary, i.e. `target/page`).
    #[arg(long)]
    pub page: Option<PathBuf>,
    /// Token of the experimenter's dashboard (`/dashboard.html#TOKEN`); without it there is
    /// no dashboard.
    #[arg(long)]
    pub dashboard_token: Option<String>,
    /// Sessions and participants in a PostgreSQL database instead of a folder: any number
    /// of `study serve` processes with the same study and `--store` serve one run, behind a
    /// load balancer (docs/serve.md, "Several servers").
    #[command(flatten)]
    pub store: crate::store_args::StoreArgs,
    /// Most database connections this server opens at once (with a database).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u16).range(1..=1000))]
    pub connections: u16,
}

/// Serves `args.study` until SIGINT or SIGTERM.
///
/// # Errors
/// A bad study file or stimulus, a results folder of another study, no built page, an
/// address that cannot be bound.
pub fn run(args: &ServeArgs) -> anyhow::Result<()> {
    if args.dashboard_token.as_ref().is_some_and(|t| t.len() < 16) {
        anyhow::bail!(
            "--dashboard-token: use at least 16 characters (it guards every participant's data)"
        );
    }
    let file = StudyFile::load(&args.study)?;
    let results = args.store.destination(args.output.as_deref(), || {
        Some(file.dir().join(format!("results-{}", file.definition.name)))
    })?;
    let page = match &args.page {
        Some(p) => p.clone(),
        None => std::env::current_exe()?
            .parent()
            .and_then(std::path::Path::parent)
            .map_or_else(|| PathBuf::from("target/page"), |d| d.join("page")),
    };
    let options = web::ServeOptions {
        study: args.study.clone(),
        results,
        connections: usize::from(args.connections),
        bind: args.bind,
        page,
        dashboard_token: args.dashboard_token.clone(),
        limits: web::Limits::default(),
    };
    web::serve(options, |app, addr| {
        // One line: a caller that reads only the first line may close the pipe after it.
        let ready = match app.stimuli_ready() {
            0 => String::new(),
            n => format!("; {n} stimuli read and ready"),
        };
        println!(
            "serving {} ({}) on http://{addr}/ ; results in {}{ready}",
            app.definition().name,
            app.definition().protocol,
            app.location()
        );
        if app.has_dashboard() {
            // The token is the experimenter's to add; it stays out of logs.
            println!("dashboard: http://{addr}/dashboard.html#<the --dashboard-token>");
        }
        if !addr.ip().is_loopback() {
            println!(
                "note: listening beyond this machine; serve participants through a TLS reverse proxy (docs/serve.md)"
            );
        }
    })?;
    println!("stopped; open sessions are saved and continue when the server runs again");
    Ok(())
}
