//! The solver's queue of the page's commands: at most [`MAX_QUEUED`] wait, and one more is
//! refused (the page is told, and the server holds a bounded amount however fast a page
//! sends). A command that carries the whole state ([`Newest`]: an edit) replaces one of its
//! kind queued just before it: of the poses a drag sends while the solver works, only the
//! newest waits, and a drag never fills the queue.
//!
//! The connections hold [`Commands`] (one each, cloned); the solver thread holds the
//! [`Inbox`] and blocks on it (a condition variable, no polling). The inbox says
//! [`RecvTimeoutError::Disconnected`] once every sender is gone and nothing waits; a send
//! fails once the inbox is gone.

use std::collections::VecDeque;
use std::sync::mpsc::RecvTimeoutError;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

/// The most commands waiting for the solver. A command holds at most what one message of
/// [`MAX_MESSAGE`](super::MAX_MESSAGE) bytes carries (its JSON parsed is no larger), so the
/// queue holds at most 32 MiB; the page itself has a few commands in flight (a selection,
/// an edit, a release, a save, an apply).
pub const MAX_QUEUED: usize = 32;

/// A command that may make the one queued just before it stale.
pub(super) trait Newest {
    /// Whether `self` makes `older`, queued just before it, stale (it is dropped unanswered).
    fn replaces(&self, older: &Self) -> bool;
}

/// What the queue holds, behind its lock.
struct State<T> {
    requests: VecDeque<T>,
    /// The [`Commands`] alive.
    senders: usize,
    /// Whether the [`Inbox`] is alive.
    open: bool,
}

struct Shared<T> {
    state: Mutex<State<T>>,
    /// Signalled on each command queued and when the last sender goes.
    ready: Condvar,
}

impl<T> Shared<T> {
    fn lock(&self) -> MutexGuard<'_, State<T>> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Why a command was not queued.
pub(super) enum Refused<T> {
    /// [`MAX_QUEUED`] commands wait: the command, given back.
    Full(Box<T>),
    /// The solver is gone.
    Closed,
}

/// The sending end: one per connection.
pub(super) struct Commands<T>(Arc<Shared<T>>);

/// The receiving end: the solver thread's.
pub(super) struct Inbox<T>(Arc<Shared<T>>);

/// A new queue, empty.
pub(super) fn queue<T>() -> (Commands<T>, Inbox<T>) {
    let shared = Arc::new(Shared {
        state: Mutex::new(State {
            requests: VecDeque::new(),
            senders: 1,
            open: true,
        }),
        ready: Condvar::new(),
    });
    (Commands(shared.clone()), Inbox(shared))
}

impl<T: Newest> Commands<T> {
    /// Queues `request`; one that [replaces](Newest::replaces) the command queued last takes
    /// its place (which is then never answered: the page sent a newer state).
    pub(super) fn send(&self, request: T) -> Result<(), Refused<T>> {
        let mut state = self.0.lock();
        if !state.open {
            return Err(Refused::Closed);
        }
        if state
            .requests
            .back()
            .is_some_and(|older| request.replaces(older))
        {
            state.requests.pop_back();
        } else if state.requests.len() >= MAX_QUEUED {
            return Err(Refused::Full(Box::new(request)));
        }
        state.requests.push_back(request);
        drop(state);
        self.0.ready.notify_one();
        Ok(())
    }
}

impl<T> Clone for Commands<T> {
    fn clone(&self) -> Self {
        self.0.lock().senders += 1;
        Self(self.0.clone())
    }
}

impl<T> Drop for Commands<T> {
    fn drop(&mut self) {
        let mut state = self.0.lock();
        state.senders -= 1;
        if state.senders == 0 {
            drop(state);
            self.0.ready.notify_all();
        }
    }
}

impl<T> Inbox<T> {
    /// The oldest command: waiting for one without end (`wait` `None`) or for at most `wait`
    /// (zero: only one already there); `Disconnected` when none waits and no sender is left.
    pub(super) fn next(&self, wait: Option<Duration>) -> Result<T, RecvTimeoutError> {
        let mut state = self.0.lock();
        let deadline = wait.map(|w| std::time::Instant::now() + w);
        loop {
            if let Some(request) = state.requests.pop_front() {
                return Ok(request);
            }
            if state.senders == 0 {
                return Err(RecvTimeoutError::Disconnected);
            }
            state = match deadline {
                None => self.0.ready.wait(state).unwrap_or_else(|p| p.into_inner()),
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(std::time::Instant::now());
                    if left.is_zero() {
                        return Err(RecvTimeoutError::Timeout);
                    }
                    self.0
                        .ready
                        .wait_timeout(state, left)
                        .unwrap_or_else(|p| p.into_inner())
                        .0
                }
            };
        }
    }
}

impl<T> Drop for Inbox<T> {
    fn drop(&mut self) {
        let mut state = self.0.lock();
        state.open = false;
        state.requests.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A command as the queue sees it: an edit (which replaces an edit) or another.
    #[derive(Debug, PartialEq)]
    enum Item {
        Edit(u32),
        Other(u32),
    }

    impl Newest for Item {
        fn replaces(&self, older: &Self) -> bool {
            matches!((self, older), (Item::Edit(_), Item::Edit(_)))
        }
    }

    /// At most [`MAX_QUEUED`] commands wait, one more is given back; taking one makes room.
    #[test]
    fn the_queue_is_bounded() {
        let (commands, inbox) = queue();
        for k in 0..MAX_QUEUED as u32 {
            assert!(commands.send(Item::Other(k)).is_ok());
        }
        let Err(Refused::Full(given)) = commands.send(Item::Other(99)) else {
            panic!("queued past the bound");
        };
        assert_eq!(*given, Item::Other(99));
        assert!(matches!(
            commands.send(Item::Edit(1)),
            Err(Refused::Full(_))
        ));
        assert_eq!(inbox.next(None).ok(), Some(Item::Other(0)));
        assert!(commands.send(Item::Other(100)).is_ok());
    }

    /// An edit replaces the edit queued last, so a drag never fills the queue; a command
    /// between two edits keeps both.
    #[test]
    fn an_edit_replaces_the_edit_before_it() {
        let (commands, inbox) = queue();
        let last = 10 * MAX_QUEUED as u32;
        for k in 0..=last {
            assert!(commands.send(Item::Edit(k)).is_ok());
        }
        assert!(commands.send(Item::Other(1)).is_ok());
        assert!(commands.send(Item::Edit(1000)).is_ok());
        let zero = Some(Duration::ZERO);
        assert_eq!(inbox.next(zero).ok(), Some(Item::Edit(last)));
        assert_eq!(inbox.next(zero).ok(), Some(Item::Other(1)));
        assert_eq!(inbox.next(zero).ok(), Some(Item::Edit(1000)));
        assert!(matches!(inbox.next(zero), Err(RecvTimeoutError::Timeout)));
        drop(commands);
        assert!(matches!(
            inbox.next(None),
            Err(RecvTimeoutError::Disconnected)
        ));
    }

    /// A send after the solver is gone fails.
    #[test]
    fn a_send_without_the_solver_fails() {
        let (commands, inbox) = queue();
        drop(inbox);
        assert!(matches!(
            commands.send(Item::Other(1)),
            Err(Refused::Closed)
        ));
    }
}
