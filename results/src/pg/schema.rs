//! The database schema, versioned: `study_schema_version` holds one row per migration
//! applied. Migrations are applied in one transaction under a transaction-level advisory lock
//! (so two stations starting at once apply them once), and a database whose schema is newer
//! than this build knows is refused rather than written in an older layout.

use postgres::Client;

use super::{LOCK_NAMESPACE, db_error};
use crate::ResultsError;

/// The migrations, in order; migration `i` (1-based) brings the schema to version `i`.
/// Documented in `docs/postgres.md`. Version 2 added the between-subject group assignments;
/// version 3 the subject id each number was taken for and, for a simulated subject, the
/// observer seed (numbers taken before it have neither), so that a number whose session was
/// never created can be found and its session created.
pub const MIGRATIONS: &[&str] = &[
    r"
CREATE TABLE study_runs (
    id integer GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    name text NOT NULL UNIQUE,
    study text NOT NULL,
    study_hash text NOT NULL,
    manifest_hash text,
    run_manifest jsonb NOT NULL,
    study_copy bytea NOT NULL,
    manifest_copy bytea NOT NULL,
    next_subject integer NOT NULL DEFAULT 1 CHECK (next_subject > 0)
);
CREATE TABLE study_subject_numbers (
    run_id integer NOT NULL REFERENCES study_runs (id),
    number integer NOT NULL,
    station text NOT NULL,
    allocated_at timestamptz NOT NULL DEFAULT now(),
    PRIMARY KEY (run_id, number)
);
CREATE TABLE study_sessions (
    id integer GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    run_id integer NOT NULL REFERENCES study_runs (id),
    subject text NOT NULL,
    session integer NOT NULL,
    study_hash text NOT NULL,
    manifest_hash text,
    status text NOT NULL,
    trials_logged integer NOT NULL,
    trials_format_version integer NOT NULL,
    manifest jsonb NOT NULL,
    UNIQUE (run_id, subject, session)
);
CREATE TABLE study_trials (
    session_id integer NOT NULL REFERENCES study_sessions (id),
    row_number integer NOT NULL,
    study text NOT NULL,
    subject text NOT NULL,
    session integer NOT NULL,
    trial_index integer NOT NULL,
    block text NOT NULL,
    protocol text NOT NULL,
    condition text NOT NULL,
    stimulus text NOT NULL,
    reference text NOT NULL,
    arrangement text NOT NULL,
    reference_position text NOT NULL,
    break_before boolean NOT NULL,
    staircase integer,
    level double precision,
    response double precision,
    response_a double precision,
    response_b double precision,
    choice text,
    score double precision NOT NULL,
    score_reference double precision,
    score_test double precision,
    correct boolean,
    reversal boolean,
    response_time_ms bigint NOT NULL,
    replays integer NOT NULL,
    dropped_frames integer NOT NULL,
    elapsed_ms bigint NOT NULL,
    wall_clock_ms bigint NOT NULL,
    monotonic_ms bigint NOT NULL,
    codec_params text,
    achieved_cr double precision,
    rms_cm double precision,
    frames_shown integer,
    interval_sd_ms double precision,
    PRIMARY KEY (session_id, row_number)
);
CREATE TABLE study_session_files (
    session_id integer NOT NULL REFERENCES study_sessions (id),
    name text NOT NULL,
    part integer NOT NULL,
    bytes bytea NOT NULL,
    PRIMARY KEY (session_id, name, part)
);
-- Whether this connection holds the writer's lock of a session (a station inserts rows only
-- into the sessions it holds).
CREATE FUNCTION study_holds_session(session_id integer) RETURNS boolean
    LANGUAGE sql STABLE AS $$
    SELECT EXISTS (
        SELECT 1 FROM pg_locks
        WHERE locktype = 'advisory' AND pid = pg_backend_pid() AND granted
          AND classid = 1398035780::bigint::oid AND objid = session_id::bigint::oid
          AND objsubid = 2)
$$;
ALTER TABLE study_trials ENABLE ROW LEVEL SECURITY;
CREATE POLICY study_trials_read ON study_trials FOR SELECT USING (true);
CREATE POLICY study_trials_insert ON study_trials FOR INSERT
    WITH CHECK (study_holds_session(session_id));
ALTER TABLE study_session_files ENABLE ROW LEVEL SECURITY;
CREATE POLICY study_session_files_read ON study_session_files FOR SELECT USING (true);
CREATE POLICY study_session_files_insert ON study_session_files FOR INSERT
    WITH CHECK (study_holds_session(session_id));
CREATE POLICY study_session_files_delete ON study_session_files FOR DELETE
    USING (study_holds_session(session_id));
ALTER TABLE study_sessions ENABLE ROW LEVEL SECURITY;
CREATE POLICY study_sessions_read ON study_sessions FOR SELECT USING (true);
CREATE POLICY study_sessions_insert ON study_sessions FOR INSERT WITH CHECK (true);
CREATE POLICY study_sessions_update ON study_sessions FOR UPDATE
    USING (study_holds_session(id));
CREATE POLICY study_sessions_delete ON study_sessions FOR DELETE
    USING (study_holds_session(id) AND trials_logged = 0);
",
    r"
CREATE TABLE study_group_assignments (
    run_id integer NOT NULL REFERENCES study_runs (id),
    subject text NOT NULL,
    session integer NOT NULL,
    group_name text NOT NULL,
    ordinal integer NOT NULL CHECK (ordinal >= 0),
    station text NOT NULL,
    assigned_at timestamptz NOT NULL DEFAULT now(),
    PRIMARY KEY (run_id, subject, session),
    UNIQUE (run_id, group_name, ordinal)
);
",
    r"
ALTER TABLE study_subject_numbers ADD COLUMN subject text, ADD COLUMN observer_seed bigint;
",
    // `study serve --store`: the participants of a run served in browsers, shared by every
    // server of the run. Times are the database server's clock, the one clock all servers
    // share: when the participant last made a request (their place against a quota is held
    // for the study's lease from then) and when their pending trial was last sent.
    r"
CREATE TABLE study_participants (
    run_id integer NOT NULL REFERENCES study_runs (id),
    subject text NOT NULL,
    token_sha256 bytea NOT NULL UNIQUE CHECK (length(token_sha256) = 32),
    source text NOT NULL,
    ids jsonb NOT NULL,
    plan_group integer CHECK (plan_group >= 0),
    joined_at timestamptz NOT NULL DEFAULT clock_timestamp(),
    last_seen timestamptz NOT NULL DEFAULT clock_timestamp(),
    finished boolean NOT NULL DEFAULT false,
    sent_index integer,
    sent_at timestamptz,
    PRIMARY KEY (run_id, subject)
);
",
];

/// The schema version this build writes and reads.
pub const SCHEMA_VERSION: i32 = MIGRATIONS.len() as i32;

/// The schema version of the database `client` is connected to (0: none).
///
/// # Errors
/// The version table cannot be read.
pub fn version(client: &mut Client, location: &str) -> Result<i32, ResultsError> {
    let exists: bool = client
        .query_one(
            "SELECT to_regclass('study_schema_version') IS NOT NULL",
            &[],
        )
        .and_then(|r| r.try_get(0))
        .map_err(|e| db_error(location, "reading the schema version", &e))?;
    if !exists {
        return Ok(0);
    }
    client
        .query_one(
            "SELECT coalesce(max(version), 0) FROM study_schema_version",
            &[],
        )
        .and_then(|r| r.try_get(0))
        .map_err(|e| db_error(location, "reading the schema version", &e))
}

fn newer(location: &str, found: i32) -> ResultsError {
    ResultsError::Schema {
        location: location.to_owned(),
        message: format!(
            "its schema is version {found}, newer than this build knows ({SCHEMA_VERSION}); \
             use the `study` that made it, or a newer one"
        ),
    }
}

/// Brings the schema up to [`SCHEMA_VERSION`]: nothing when it is there already (what a
/// station role without the right to create tables needs), else the missing migrations in one
/// transaction. A newer schema is refused.
///
/// # Errors
/// [`ResultsError::Schema`] for a newer schema, database errors (a role that may not create
/// the tables among them).
pub fn migrate(client: &mut Client, location: &str) -> Result<i32, ResultsError> {
    let found = version(client, location)?;
    if found > SCHEMA_VERSION {
        return Err(newer(location, found));
    }
    if found == SCHEMA_VERSION {
        return Ok(found);
    }
    let err = |e: postgres::Error| db_error(location, "creating the results schema", &e);
    let mut tx = client.transaction().map_err(err)?;
    // Stations that start together wait here for the first one's migrations.
    tx.execute("SELECT pg_advisory_xact_lock($1, 0)", &[&LOCK_NAMESPACE])
        .map_err(err)?;
    tx.batch_execute(
        "CREATE TABLE IF NOT EXISTS study_schema_version (
            version integer PRIMARY KEY,
            applied_at timestamptz NOT NULL DEFAULT now(),
            software text NOT NULL)",
    )
    .map_err(err)?;
    let now: i32 = tx
        .query_one(
            "SELECT coalesce(max(version), 0) FROM study_schema_version",
            &[],
        )
        .and_then(|r| r.try_get(0))
        .map_err(err)?;
    if now > SCHEMA_VERSION {
        return Err(newer(location, now));
    }
    let software = concat!("study ", env!("CARGO_PKG_VERSION"));
    for (i, sql) in MIGRATIONS.iter().enumerate().skip(now as usize) {
        let v = i as i32 + 1;
        tx.batch_execute(sql).map_err(err)?;
        tx.execute(
            "INSERT INTO study_schema_version (version, software) VALUES ($1, $2)",
            &[&v, &software],
        )
        .map_err(err)?;
    }
    tx.commit().map_err(err)?;
    Ok(SCHEMA_VERSION)
}
