//! A bounded pool of connections, for a process that serves many sessions at once (`study
//! serve --store`): a request borrows a connection for one transaction and gives it back, so
//! that thousands of open sessions need no connection each (a PostgreSQL server takes about a
//! hundred by default; each is a server process).

use std::cell::Cell;
use std::ops::{Deref, DerefMut};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

use postgres::Client;

use super::Database;
use crate::ResultsError;

thread_local! {
    /// Connections of any pool this thread holds.
    static HELD: Cell<usize> = const { Cell::new(0) };
}

/// How long a caller waits for a connection when all are lent out.
const WAIT: Duration = Duration::from_secs(10);

/// Connections to one database, at most `max` at once.
pub struct Pool {
    db: Database,
    max: usize,
    state: Mutex<State>,
    freed: Condvar,
}

#[derive(Default)]
struct State {
    idle: Vec<Client>,
    /// Connections lent out or being made.
    out: usize,
}

impl std::fmt::Debug for Pool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Pool({}, at most {})", self.db.shown(), self.max)
    }
}

impl Pool {
    /// A pool of at most `max` (at least 1) connections to `db`, made as they are needed.
    pub fn new(db: &Database, max: usize) -> Arc<Pool> {
        Arc::new(Pool {
            db: db.clone(),
            max: max.max(1),
            state: Mutex::new(State::default()),
            freed: Condvar::new(),
        })
    }

    /// The database.
    pub fn database(&self) -> &Database {
        &self.db
    }

    /// A connection: an idle one, a new one while fewer than `max` exist, else the next one
    /// given back (waiting up to 10 s).
    ///
    /// # Errors
    /// [`ResultsError::Unavailable`] when none came back in time or the server cannot be
    /// reached.
    pub fn get(self: &Arc<Self>) -> Result<Pooled, ResultsError> {
        let deadline = Instant::now() + WAIT;
        // A thread that holds one already (a request's store, asking for its session's
        // writer) never waits: waiting for another thread's would deadlock once every
        // connection is held by one waiting so. Such second connections may take the pool
        // to twice `max`.
        let nested = HELD.with(Cell::get) > 0;
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            while let Some(client) = state.idle.pop() {
                if client.is_closed() {
                    continue;
                }
                state.out += 1;
                return Ok(self.lend(client));
            }
            if state.out < self.max || nested && state.out < 2 * self.max {
                state.out += 1;
                drop(state);
                return match self.db.connect() {
                    Ok(client) => Ok(self.lend(client)),
                    Err(e) => {
                        self.give_back(None);
                        Err(e)
                    }
                };
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(ResultsError::Unavailable {
                    location: self.db.shown().to_owned(),
                    op: "waiting for a connection".into(),
                    message: format!(
                        "all {} of this process's connections stayed busy for {} s",
                        self.max,
                        WAIT.as_secs()
                    ),
                });
            }
            state = self
                .freed
                .wait_timeout(state, left)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    fn lend(self: &Arc<Self>, client: Client) -> Pooled {
        HELD.with(|h| h.set(h.get() + 1));
        Pooled {
            pool: Arc::clone(self),
            client: Some(client),
        }
    }

    fn give_back(&self, client: Option<Client>) {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        state.out = state.out.saturating_sub(1);
        if let Some(c) = client.filter(|c| !c.is_closed()) {
            state.idle.push(c);
        }
        drop(state);
        self.freed.notify_one();
    }
}

/// A connection lent by a [`Pool`], given back when dropped (a closed one is let go).
pub struct Pooled {
    pool: Arc<Pool>,
    client: Option<Client>,
}

impl Pooled {
    /// Lets the connection go instead of giving it back (its state is unknown: an error in
    /// the middle of a transaction).
    pub fn discard(mut self) {
        self.client = None;
    }
}

impl Deref for Pooled {
    type Target = Client;
    fn deref(&self) -> &Client {
        // Always `Some` until dropped.
        self.client
            .as_ref()
            .unwrap_or_else(|| unreachable!("a pooled connection after its drop"))
    }
}

impl DerefMut for Pooled {
    fn deref_mut(&mut self) -> &mut Client {
        self.client
            .as_mut()
            .unwrap_or_else(|| unreachable!("a pooled connection after its drop"))
    }
}

impl Drop for Pooled {
    fn drop(&mut self) {
        HELD.with(|h| h.set(h.get().saturating_sub(1)));
        self.pool.give_back(self.client.take());
    }
}
