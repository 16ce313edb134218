//! Catching a third-party parser's panic without its message reaching stderr.
//!
//! `c3dio` indexes its input without bounds checks in places, so a malformed C3D file can
//! make it panic. [`catch_quiet`] runs such a call under `catch_unwind` and keeps the panic
//! hook from printing for panics *of the calling thread while the call runs*; the caller turns
//! the panic into its own typed error, which is then the only message the user sees.
//!
//! The panic hook is process-global, so swapping it for a silent one would also silence (or,
//! raced, lose) other threads' panics. Instead, while any call is active, a wrapper hook is
//! installed that stays silent only on threads that are inside [`catch_quiet`] (a thread-local
//! depth) and hands every other panic to the hook that was installed before. When the last
//! active call ends the previous hook is put back, unless someone else replaced the wrapper in
//! the meantime (theirs is then left in place). No global state outlives the calls.

use std::any::Any;
use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe, PanicHookInfo};
use std::sync::{Arc, Mutex, PoisonError};

type Hook = Box<dyn Fn(&PanicHookInfo<'_>) + Sync + Send + 'static>;

thread_local! {
    /// How many [`catch_quiet`] calls this thread is inside.
    static QUIET_DEPTH: Cell<usize> = const { Cell::new(0) };
}

/// Active calls over all threads, the hook that was installed before the first of them, and
/// the address of the wrapper installed in its place.
struct Installed {
    active: usize,
    previous: Option<Arc<Hook>>,
    wrapper: usize,
}

static INSTALLED: Mutex<Installed> = Mutex::new(Installed {
    active: 0,
    previous: None,
    wrapper: 0,
});

fn quiet_here() -> bool {
    QUIET_DEPTH.try_with(|d| d.get() > 0).unwrap_or(false)
}

/// Address of a hook's closure, to recognise our wrapper when it is taken back.
fn address(hook: &Hook) -> usize {
    std::ptr::from_ref::<dyn Fn(&PanicHookInfo<'_>) + Sync + Send>(hook.as_ref()).cast::<u8>()
        as usize
}

fn enter() {
    let mut state = INSTALLED.lock().unwrap_or_else(PoisonError::into_inner);
    if state.active == 0 {
        let previous = Arc::new(panic::take_hook());
        let inner = Arc::clone(&previous);
        let wrapper: Hook = Box::new(move |info| {
            if !quiet_here() {
                inner(info);
            }
        });
        state.wrapper = address(&wrapper);
        state.previous = Some(previous);
        panic::set_hook(wrapper);
    }
    state.active += 1;
}

fn leave() {
    let mut state = INSTALLED.lock().unwrap_or_else(PoisonError::into_inner);
    state.active = state.active.saturating_sub(1);
    if state.active > 0 {
        return;
    }
    let current = panic::take_hook();
    if address(&current) == state.wrapper {
        // Ours: dropping it releases its share of the previous hook, which goes back.
        drop(current);
        if let Some(previous) = state.previous.take() {
            match Arc::try_unwrap(previous) {
                Ok(hook) => panic::set_hook(hook),
                // Unreachable while the wrapper held the only other share; keep printing.
                Err(shared) => panic::set_hook(Box::new(move |info| shared(info))),
            }
        }
    } else {
        // Someone installed their own hook meanwhile: leave theirs.
        panic::set_hook(current);
        state.previous = None;
    }
    state.wrapper = 0;
}

/// Text of a panic payload (`&str` or `String`), else a placeholder.
pub fn payload_text(payload: &(dyn Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".to_string())
}

/// Runs `f`, catching a panic as `Err(message)` without the panic hook printing it. Other
/// threads' panics are reported as usual meanwhile (see the module docs).
///
/// # Errors
/// The panic's message when `f` panicked.
pub fn catch_quiet<R>(f: impl FnOnce() -> R) -> Result<R, String> {
    enter();
    QUIET_DEPTH.with(|d| d.set(d.get() + 1));
    let result = panic::catch_unwind(AssertUnwindSafe(f));
    QUIET_DEPTH.with(|d| d.set(d.get().saturating_sub(1)));
    leave();
    result.map_err(|payload| payload_text(payload.as_ref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_its_message() {
        let r: Result<(), String> = catch_quiet(|| panic!("index out of bounds: 7"));
        assert_eq!(r, Err("index out of bounds: 7".to_string()));
        assert_eq!(catch_quiet(|| 5), Ok(5));
    }

    #[test]
    fn nested_calls_stay_quiet_until_the_outer_one_ends() {
        let r = catch_quiet(|| {
            let inner: Result<(), String> = catch_quiet(|| panic!("inner"));
            assert!(quiet_here());
            inner
        });
        assert_eq!(r, Ok(Err("inner".to_string())));
        assert!(!quiet_here());
    }
}
