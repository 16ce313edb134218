//! `--store`, `--store-file` and `--run`: where a command keeps or finds results, a folder or
//! a PostgreSQL database (`docs/postgres.md`). A connection string's password never comes
//! from the command line (where `ps` and the shell's history would show it) and is never
//! printed.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
use lab::results_dir::Destination;
use results::pg::{Database, STORE_ENV};

/// Where results are kept.
#[derive(Debug, Clone, Default, Args)]
pub struct StoreArgs {
    /// Results store: a folder, a PostgreSQL URL without a password
    /// (`postgres://station@db.lab/study`; the password from PGPASSWORD), or `env` for the
    /// connection string in $STUDY_DATABASE_URL (`env:NAME` for another variable).
    #[arg(long, value_name = "STORE")]
    pub store: Option<String>,
    /// A file holding the PostgreSQL connection string (readable by its owner only).
    #[arg(long, value_name = "FILE", conflicts_with = "store")]
    pub store_file: Option<PathBuf>,
    /// The run in the database (default: the study's name; for a command without a study
    /// file, the database's one run).
    #[arg(long, value_name = "NAME")]
    pub run: Option<String>,
}

impl StoreArgs {
    /// The database these arguments name, if they name one (`None`: a folder, or nothing).
    ///
    /// # Errors
    /// A connection string that does not parse, a password on the command line, an unset
    /// variable, a file others can read.
    pub fn database(&self) -> Result<Option<Database>> {
        if let Some(file) = &self.store_file {
            return Ok(Some(Database::from_file(file)?));
        }
        let Some(store) = &self.store else {
            return Ok(None);
        };
        Ok(if results::pg::is_url(store) {
            Some(Database::from_argument(store)?)
        } else if store == "env" {
            Some(Database::from_env(STORE_ENV)?)
        } else if let Some(var) = store.strip_prefix("env:") {
            Some(Database::from_env(var)?)
        } else {
            None
        })
    }

    /// Where a command that writes results writes them: the database, or the folder of
    /// `--store`, else `output` (`-o`), else `default`.
    ///
    /// # Errors
    /// As [`Self::database`]; `--run` without a database; both `--store` and `-o`.
    pub fn destination(
        &self,
        output: Option<&Path>,
        default: impl FnOnce() -> Option<PathBuf>,
    ) -> Result<Destination> {
        let db = self.database()?;
        if self.run.is_some() && db.is_none() {
            bail!("--run names a run of a database; it needs --store with a database");
        }
        if let Some(db) = db {
            if output.is_some() {
                bail!("-o names a results folder; results go to the database of --store instead");
            }
            return Ok(Destination::Database {
                db: Box::new(db),
                run: self.run.clone(),
            });
        }
        match (&self.store, output) {
            (Some(_), Some(_)) => bail!("give the results folder once: --store or -o"),
            (Some(folder), None) => Ok(Destination::Folder(PathBuf::from(folder))),
            (None, Some(out)) => Ok(Destination::Folder(out.to_path_buf())),
            (None, None) => default().map(Destination::Folder).ok_or_else(|| {
                anyhow::anyhow!("say where the results go: -o FOLDER or --store STORE")
            }),
        }
    }
}
