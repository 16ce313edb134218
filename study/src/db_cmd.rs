//! `study export`, `study import` and `study db-init`: results between a PostgreSQL database
//! and results folders, and the database's schema (`docs/postgres.md`).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use results::pg::{self, Database, PgStore};

use crate::store_args::StoreArgs;

/// Arguments of `study export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The database (and `--run`).
    #[command(flatten)]
    pub store: StoreArgs,
    /// Results folder to write (new or empty).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
}

/// Arguments of `study import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// Results folder to load (written by `study run`, `study simulate` or `study export`).
    pub folder: PathBuf,
    /// The database, and the run to load into (`--run`; default: the folder's study name).
    #[command(flatten)]
    pub store: StoreArgs,
}

/// Arguments of `study db-init`.
#[derive(Debug, Args)]
pub struct DbInitArgs {
    /// The database.
    #[command(flatten)]
    pub store: StoreArgs,
}

fn database(args: &StoreArgs) -> Result<Database> {
    match args.database()? {
        Some(db) => Ok(db),
        None => bail!(
            "--store names no database: give a postgres:// URL, `env` ($STUDY_DATABASE_URL) or --store-file"
        ),
    }
}

/// `study export --store DB [--run NAME] -o FOLDER`.
///
/// # Errors
/// No database named, the run does not exist, the folder holds anything, database or I/O
/// errors.
pub fn export(args: &ExportArgs) -> Result<()> {
    let db = database(&args.store)?;
    let mut store = PgStore::open(&db, args.store.run.as_deref())?;
    let n = pg::export(&mut store, &args.output)?;
    println!(
        "{}: {n} sessions of run {:?} from {}",
        args.output.display(),
        store.name(),
        db.shown()
    );
    Ok(())
}

/// `study import FOLDER --store DB [--run NAME]`.
///
/// # Errors
/// No database named, a malformed folder, sessions already in the run, database errors.
pub fn import(args: &ImportArgs) -> Result<()> {
    let db = database(&args.store)?;
    let (name, n) = pg::import(&db, &args.folder, args.store.run.as_deref())?;
    println!(
        "{}: {n} sessions loaded into run {name:?} of {}",
        args.folder.display(),
        db.shown()
    );
    Ok(())
}

/// `study db-init --store DB`.
///
/// # Errors
/// No database named, a schema newer than this build's, database errors (a role that may
/// not create tables among them).
pub fn init(args: &DbInitArgs) -> Result<()> {
    let db = database(&args.store)?;
    let mut client = db.open()?;
    let runs = pg::runs(&mut client, db.shown())?;
    let mut text = format!(
        "{}: results schema version {}; {} runs",
        db.shown(),
        pg::schema::SCHEMA_VERSION,
        runs.len()
    );
    for r in &runs {
        let _ = write!(
            text,
            "\n  {} ({} sessions of study {:?})",
            r.name, r.sessions, r.run.study
        );
    }
    println!("{text}");
    Ok(())
}
