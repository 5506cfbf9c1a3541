//! The one worker pool of the workspace (episode generation, evaluation, the expert's success
//! table): items `0..n` handed out in order to a few threads, each with its own state (a
//! simulator, a policy), stopping at the first error.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Runs `work(&mut state, k)` for every k in `0..items` on `workers` threads (at most `items`).
///
/// Each thread builds its state with `init` before its first item. Items are handed out in
/// increasing order; after the first error no new item starts, and that error (the first one
/// returned) is the result. A worker that panics makes the result `panicked()`.
pub fn for_each<S, E: Send>(
    items: usize,
    workers: usize,
    init: impl Fn() -> Result<S, E> + Sync,
    work: impl Fn(&mut S, usize) -> Result<(), E> + Sync,
    panicked: impl Fn() -> E,
) -> Result<(), E> {
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let worker = || -> Result<(), E> {
        let run = || -> Result<(), E> {
            let mut state = None;
            loop {
                let k = next.fetch_add(1, Ordering::SeqCst);
                if k >= items || stop.load(Ordering::SeqCst) {
                    return Ok(());
                }
                if state.is_none() {
                    state = Some(init()?);
                }
                work(state.as_mut().expect("just built"), k)?;
            }
        };
        let r = run();
        if r.is_err() {
            stop.store(true, Ordering::SeqCst);
        }
        r
    };
    let outcomes: Vec<Option<Result<(), E>>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers.clamp(1, items.max(1)))
            .map(|_| s.spawn(worker))
            .collect();
        handles.into_iter().map(|h| h.join().ok()).collect()
    });
    for o in outcomes {
        match o {
            Some(r) => r?,
            None => return Err(panicked()),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn every_item_once_and_the_first_error_stops_the_rest() {
        for workers in [1, 2, 5] {
            let seen = Mutex::new(vec![]);
            for_each(
                10,
                workers,
                || Ok::<_, String>(()),
                |_, k| {
                    seen.lock().unwrap().push(k);
                    Ok(())
                },
                || "panic".to_string(),
            )
            .unwrap();
            let mut v = seen.into_inner().unwrap();
            v.sort();
            assert_eq!(v, (0..10).collect::<Vec<_>>());
        }
        let started = AtomicUsize::new(0);
        let e = for_each(
            1000,
            1,
            || Ok::<_, String>(()),
            |_, k| {
                started.fetch_add(1, Ordering::SeqCst);
                if k == 3 {
                    Err(format!("item {k}"))
                } else {
                    Ok(())
                }
            },
            || "panic".to_string(),
        )
        .unwrap_err();
        assert_eq!(e, "item 3");
        assert_eq!(started.load(Ordering::SeqCst), 4);
        let e = for_each(
            2,
            2,
            || Ok::<_, String>(()),
            |_, k| if k == 1 { panic!("boom") } else { Ok(()) },
            || "a worker panicked".to_string(),
        )
        .unwrap_err();
        assert_eq!(e, "a worker panicked");
        // init failures are errors too, and no items: nothing runs.
        let e = for_each(
            3,
            2,
            || Err::<(), _>("no env".to_string()),
            |_, _| Ok(()),
            String::new,
        );
        assert_eq!(e.unwrap_err(), "no env");
        for_each(
            0,
            2,
            || Err::<(), _>("never".to_string()),
            |_, _| Ok(()),
            String::new,
        )
        .unwrap();
    }
}
