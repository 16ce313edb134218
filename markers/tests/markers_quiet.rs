//! The C3D parser's panics are caught without the panic hook printing them, and the hook the
//! process had before is the one it has after (issue 9: malformed C3D gives one clear error).
//!
//! One test function: the panic hook is process-global, and this test replaces it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use markers::quiet::catch_quiet;

#[test]
fn quiet_panics_leave_other_threads_and_the_previous_hook_alone() {
    let calls = Arc::new(AtomicUsize::new(0));
    let counter = Arc::clone(&calls);
    std::panic::set_hook(Box::new(move |_| {
        counter.fetch_add(1, Ordering::SeqCst);
    }));

    // A quiet panic: caught, its message returned, the hook not called.
    let r: Result<(), String> = catch_quiet(|| panic!("c3dio: index out of bounds"));
    assert_eq!(r, Err("c3dio: index out of bounds".to_string()));
    assert_eq!(calls.load(Ordering::SeqCst), 0);

    // While one thread is inside a quiet call, another thread's panic still reaches the hook.
    let (inside_tx, inside_rx) = std::sync::mpsc::channel();
    let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
    let quiet = std::thread::spawn(move || {
        catch_quiet(|| {
            inside_tx.send(()).unwrap();
            done_rx.recv().unwrap();
            panic!("quiet")
        })
    });
    inside_rx.recv().unwrap();
    let loud = std::thread::spawn(|| panic!("loud")).join();
    assert!(loud.is_err());
    assert_eq!(
        calls.load(Ordering::SeqCst),
        1,
        "the other thread's panic was reported"
    );
    done_tx.send(()).unwrap();
    let r: Result<(), String> = quiet.join().unwrap();
    assert_eq!(r, Err("quiet".to_string()));
    assert_eq!(calls.load(Ordering::SeqCst), 1, "the quiet panic was not");

    // Many threads at once: every quiet panic is caught, none reported.
    let workers: Vec<_> = (0..8)
        .map(|i| {
            std::thread::spawn(move || {
                (0..50)
                    .filter(|k| catch_quiet(|| assert!((i + k) % 3 != 0, "bad")).is_err())
                    .count()
            })
        })
        .collect();
    let caught: usize = workers.into_iter().map(|w| w.join().unwrap()).sum();
    assert_eq!(
        caught,
        (0..8)
            .map(|i| (0..50).filter(|k| (i + k) % 3 == 0).count())
            .sum()
    );
    assert_eq!(calls.load(Ordering::SeqCst), 1);

    // Afterwards the process's own hook is back: a panic outside reaches it.
    let after = std::panic::catch_unwind(|| panic!("after"));
    assert!(after.is_err());
    assert_eq!(calls.load(Ordering::SeqCst), 2);
    let _ = std::panic::take_hook();
}
