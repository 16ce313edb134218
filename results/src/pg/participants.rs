//! The participants of a run served in browsers by one or more `study serve --store`
//! processes (`study_participants`): who they are, the SHA-256 of their token, their plan
//! group, whether their session is over, when they last made a request and when their
//! pending trial was last sent, both by the database server's clock (the one clock every
//! server shares). A join counts the places held and inserts the newcomer in one transaction
//! that holds the run's row, so servers joining participants at once never overrun a quota.

use std::collections::BTreeMap;

use postgres::Client;

use super::db_error;
use crate::ResultsError;

/// A participant as the database holds them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParticipantRow {
    /// Subject id.
    pub subject: String,
    /// Where the id came from (`prolific`, `mturk`, `generated`).
    pub source: String,
    /// The platform's other ids.
    pub ids: BTreeMap<String, String>,
    /// Their plan group, when the study spreads participants over groups.
    pub group: Option<u32>,
    /// Their session is over.
    pub finished: bool,
}

/// The places held when a participant joins: participants in all, and per plan group
/// (`None`: no group) those whose session is over or who made a request within the lease.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Places {
    /// Every participant of the run.
    pub total: u64,
    /// Places held, by plan group.
    pub held: BTreeMap<Option<u32>, u32>,
}

/// What a request finds of its participant's session ([`touch`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Seen {
    /// The session's committed rows and status, once it exists.
    pub session: Option<(u32, String)>,
    /// The trial last sent, and how long ago (ms, by the database's clock).
    pub sent: Option<(u32, f64)>,
}

fn err<'a>(location: &'a str, op: &'static str) -> impl Fn(postgres::Error) -> ResultsError + 'a {
    move |e| db_error(location, op, &e)
}

fn group_to_sql(g: Option<u32>) -> Option<i32> {
    g.map(|g| i32::try_from(g).unwrap_or(i32::MAX))
}

fn row_of(r: &postgres::Row) -> Result<ParticipantRow, postgres::Error> {
    let ids: serde_json::Value = r.try_get(2)?;
    let group: Option<i32> = r.try_get(3)?;
    Ok(ParticipantRow {
        subject: r.try_get(0)?,
        source: r.try_get(1)?,
        ids: serde_json::from_value(ids).unwrap_or_default(),
        group: group.map(|g| g as u32),
        finished: r.try_get(4)?,
    })
}

const ROW: &str = "subject, source, ids, plan_group, finished";

/// Adds `row` with token hash `token_sha256` to run `run_id`, if `admit` lets them in:
/// `admit` sees the places held (a place is held for `lease_s` seconds from a participant's
/// last request, and for good once their session is over) and whether the subject id is
/// taken, and returns the newcomer's plan group or refuses. Joins at once, from any
/// number of servers, take turns on the run's row.
///
/// # Errors
/// `admit` refuses; database errors.
pub fn join<E: From<ResultsError>>(
    client: &mut Client,
    run_id: i32,
    location: &str,
    lease_s: u32,
    row: &ParticipantRow,
    token_sha256: &[u8; 32],
    admit: impl FnOnce(&Places, bool) -> Result<Option<u32>, E>,
) -> Result<Option<u32>, E> {
    let e = err(location, "adding a participant");
    let mut tx = client.transaction().map_err(&e)?;
    tx.execute(
        "SELECT 1 FROM study_runs WHERE id = $1 FOR UPDATE",
        &[&run_id],
    )
    .map_err(&e)?;
    let mut places = Places::default();
    let lease = f64::from(lease_s);
    for r in tx
        .query(
            "SELECT plan_group, count(*), count(*) FILTER (WHERE finished OR \
             last_seen > clock_timestamp() - make_interval(secs => $2)) \
             FROM study_participants WHERE run_id = $1 GROUP BY plan_group",
            &[&run_id, &lease],
        )
        .map_err(&e)?
    {
        let group: Option<i32> = r.try_get(0).map_err(&e)?;
        let all: i64 = r.try_get(1).map_err(&e)?;
        let held: i64 = r.try_get(2).map_err(&e)?;
        places.total += all as u64;
        places.held.insert(group.map(|g| g as u32), held as u32);
    }
    let taken = tx
        .query_opt(
            "SELECT 1 FROM study_participants WHERE run_id = $1 AND subject = $2",
            &[&run_id, &row.subject],
        )
        .map_err(&e)?
        .is_some();
    let group = admit(&places, taken)?;
    let ids = serde_json::to_value(&row.ids).map_err(|x| ResultsError::Store(x.to_string()))?;
    tx.execute(
        "INSERT INTO study_participants (run_id, subject, token_sha256, source, ids, plan_group) \
         VALUES ($1, $2, $3, $4, $5, $6)",
        &[
            &run_id,
            &row.subject,
            &token_sha256.as_slice(),
            &row.source,
            &ids,
            &group_to_sql(group),
        ],
    )
    .map_err(&e)?;
    tx.commit().map_err(&e)?;
    Ok(group)
}

/// The participant of run `run_id` whose token hashes to `token_sha256`.
///
/// # Errors
/// Database errors.
pub fn by_token(
    client: &mut Client,
    run_id: i32,
    location: &str,
    token_sha256: &[u8; 32],
) -> Result<Option<ParticipantRow>, ResultsError> {
    let e = err(location, "finding a participant");
    client
        .query_opt(
            &format!(
                "SELECT {ROW} FROM study_participants WHERE run_id = $1 AND token_sha256 = $2"
            ),
            &[&run_id, &token_sha256.as_slice()],
        )
        .map_err(&e)?
        .map(|r| row_of(&r))
        .transpose()
        .map_err(&e)
}

/// Every participant of run `run_id`, in the order they joined.
///
/// # Errors
/// Database errors.
pub fn all(
    client: &mut Client,
    run_id: i32,
    location: &str,
) -> Result<Vec<ParticipantRow>, ResultsError> {
    let e = err(location, "listing the participants");
    client
        .query(
            &format!(
                "SELECT {ROW} FROM study_participants WHERE run_id = $1 ORDER BY joined_at, subject"
            ),
            &[&run_id],
        )
        .map_err(&e)?
        .iter()
        .map(row_of)
        .collect::<Result<_, _>>()
        .map_err(&e)
}

/// Notes a request of `subject` (their place is held for the lease from now; written at
/// most every 2 s) and returns what the database holds of their session (session 1).
///
/// # Errors
/// Database errors.
pub fn touch(
    client: &mut Client,
    run_id: i32,
    location: &str,
    subject: &str,
) -> Result<Seen, ResultsError> {
    let e = err(location, "reading the participant's session");
    let row = client
        .query_opt(
            "WITH touched AS (UPDATE study_participants SET last_seen = clock_timestamp() \
               WHERE run_id = $1 AND subject = $2 \
               AND last_seen < clock_timestamp() - interval '2 seconds' RETURNING 1) \
             SELECT s.trials_logged, s.status, p.sent_index, \
               (extract(epoch FROM clock_timestamp() - p.sent_at) * 1000)::float8 \
             FROM study_participants p LEFT JOIN study_sessions s \
               ON s.run_id = p.run_id AND s.subject = p.subject AND s.session = 1 \
             WHERE p.run_id = $1 AND p.subject = $2",
            &[&run_id, &subject],
        )
        .map_err(&e)?;
    let Some(r) = row else {
        return Ok(Seen::default());
    };
    let logged: Option<i32> = r.try_get(0).map_err(&e)?;
    let status: Option<String> = r.try_get(1).map_err(&e)?;
    let sent_index: Option<i32> = r.try_get(2).map_err(&e)?;
    let ago: Option<f64> = r.try_get(3).map_err(&e)?;
    Ok(Seen {
        session: logged.zip(status).map(|(n, s)| (n.max(0) as u32, s)),
        sent: sent_index
            .zip(ago)
            .map(|(i, ms)| (i.max(0) as u32, ms.max(0.0))),
    })
}

/// Records that trial `index` of `subject`'s session is sent now (by the database's clock),
/// committed before it returns.
///
/// # Errors
/// Database errors.
pub fn record_sent(
    client: &mut Client,
    run_id: i32,
    location: &str,
    subject: &str,
    index: u32,
) -> Result<(), ResultsError> {
    let index = i32::try_from(index).unwrap_or(i32::MAX);
    client
        .execute(
            "UPDATE study_participants SET sent_index = $3, sent_at = clock_timestamp() \
             WHERE run_id = $1 AND subject = $2",
            &[&run_id, &subject, &index],
        )
        .map(drop)
        .map_err(err(location, "recording a trial sent"))
}

/// Records that `subject`'s session is over (their place against a quota is kept).
///
/// # Errors
/// Database errors.
pub fn set_finished(
    client: &mut Client,
    run_id: i32,
    location: &str,
    subject: &str,
) -> Result<(), ResultsError> {
    client
        .execute(
            "UPDATE study_participants SET finished = true WHERE run_id = $1 AND subject = $2 \
             AND NOT finished",
            &[&run_id, &subject],
        )
        .map(drop)
        .map_err(err(location, "recording a session over"))
}
