//! A client's outgoing queue, with Player's `MessageQueue` semantics.
//!
//! - PUSH mode: everything goes out in order.
//! - PULL mode: data waits until the client asks (`REQ DATA`); the ACK goes
//!   to the front, then everything queued, then `SYNCH` — only if some data
//!   was delivered, otherwise the round stays open until data comes.
//!   A response queued outside a round flushes everything ahead of it.
//! - One round is one moment: Player's Stage published every device in one
//!   server update, so a round carried them all. Here devices publish from
//!   their own processes, so before its `SYNCH` a round waits for a step
//!   newer than the last round's (data of the last step that came late
//!   goes out with it), then for all data due at the newest stamp by the
//!   pace of its own stamps (a ranger's ranges and intensities each): at
//!   most [`ROUND_WAIT`] once a newer step has come, at most [`QUIET_WAIT`]
//!   while none has. Data that misses the wait is not waited for again
//!   until it comes. A device just opened is waited for longer,
//!   up to [`OPEN_WAIT`] from its opening, until its live samples come.
//! - Replace rules (first match wins, -1 = any): ACCEPT, REPLACE the older
//!   message of the same device/type/subtype, or IGNORE. Default: accept.
//! - Bounded: DATA and CMD beyond `maxlen` are dropped and counted; in PULL
//!   mode the round then ends with `SYNCH OVERFLOW` carrying the count.
//!   Responses are never dropped (a client waits for them).

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::wire::{self, Header, PLAYER_CODE, RESP_ACK, RESP_NACK};

/// The most replace rules one client may add (distinct ones: a rule with a
/// rule's fields changes that rule). Player sets no limit; each queued
/// message is checked against every rule, on the thread that fans a
/// device's samples out to all its clients, so one client's rules would
/// slow the others. Clients add a few; beyond this the request is NACKed.
pub const MAX_RULES: usize = 64;

/// Player's `PLAYER_MSGQUEUE_DEFAULT_MAXLEN`.
pub const DEFAULT_MAXLEN: usize = 1024;

/// The longest a PULL round waits for a device's sample that is due. The
/// samples of one simulation step reach the bridge within a few
/// milliseconds of each other (Stage's, then those drivers derive from
/// them, such as rangertolaser's laser); the margin is for a loaded
/// machine. A device that stops publishing costs one round this wait
/// after the next step comes.
pub const ROUND_WAIT: Duration = Duration::from_millis(100);

/// The longest a PULL round waits for a device's sample that is due while
/// no newer step comes from any device. Samples of one step put back to
/// back by one process reached the bridge more than [`ROUND_WAIT`] apart
/// in a loaded CI run (the sender's thread was off its core), and the
/// round went without the second; until a newer step comes, the step may
/// still be arriving. A device that stops publishing when all others do
/// too costs one round this wait.
pub const QUIET_WAIT: Duration = Duration::from_secs(1);

/// The longest a PULL round waits for a device the client has just opened
/// until its live samples start, counted from the opening. The bridge
/// subscribes at the opening, and a new subscription reaches the driver
/// in milliseconds on a quiet machine but took longer than three rounds
/// once in a loaded CI run, whose rounds after the opening then went
/// without the devices (a driver just started, as rangertolaser, has no
/// latest sample to give either). A device opened that never publishes
/// again costs its first round this once.
pub const OPEN_WAIT: Duration = Duration::from_secs(2);

/// An encoded message with the header fields the queue looks at.
#[derive(Debug, Clone)]
pub struct Out {
    /// Header + body, ready for the socket. Shared between clients.
    pub bytes: Arc<[u8]>,
    /// Interface code.
    pub interf: u32,
    /// Device index.
    pub index: u32,
    /// Message type.
    pub kind: u8,
    /// Subtype.
    pub subtype: u8,
    /// The header's timestamp (a data sample's stamp).
    pub stamp: f64,
}

impl Out {
    /// Encodes `h` and `body` into a message.
    pub fn new(h: Header, body: &[u8]) -> Out {
        Out {
            bytes: wire::message(h, body).into(),
            interf: h.interf,
            index: h.index,
            kind: u8::try_from(h.kind).unwrap_or(u8::MAX),
            subtype: u8::try_from(h.subtype).unwrap_or(u8::MAX),
            stamp: h.timestamp,
        }
    }

    fn is_response(&self) -> bool {
        self.kind == RESP_ACK || self.kind == RESP_NACK
    }

    fn same_signature(&self, o: &Out) -> bool {
        (self.interf, self.index, self.kind, self.subtype) == (o.interf, o.index, o.kind, o.subtype)
    }
}

/// What a replace rule does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replace {
    /// Queue it (`PLAYER_PLAYER_MSG_REPLACE_RULE_ACCEPT`).
    Accept,
    /// Replace the queued message of the same signature (`…_REPLACE`).
    Replace,
    /// Drop it (`…_IGNORE`).
    Ignore,
}

impl Replace {
    /// From Player's number; unknown numbers accept, as Player's switch falls through.
    pub fn from_player(v: i32) -> Replace {
        match v {
            1 => Replace::Replace,
            2 => Replace::Ignore,
            _ => Replace::Accept,
        }
    }
}

/// `ADD_REPLACE_RULE`: -1 in a field matches anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rule {
    /// Interface code or -1.
    pub interf: i32,
    /// Index or -1.
    pub index: i32,
    /// Message type or -1.
    pub kind: i32,
    /// Subtype or -1.
    pub subtype: i32,
    /// What to do with a match.
    pub replace: Replace,
}

impl Rule {
    fn matches(&self, m: &Out) -> bool {
        let f = |rule: i32, v: u32| rule < 0 || rule as u32 == v;
        f(self.interf, m.interf)
            && f(self.index, m.index)
            && f(self.kind, u32::from(m.kind))
            && f(self.subtype, u32::from(m.subtype))
    }
}

/// The pace of one kind of a device's data (its interface, index and
/// subtype: a ranger's ranges and intensities are two), from the stamps of
/// its samples: what a PULL round waits for.
#[derive(Debug, Clone, Copy)]
struct Pace {
    /// Interface code, index and subtype.
    sig: (u32, u32, u8),
    /// Its newest sample's stamp.
    newest: f64,
    /// The step between its last two live stamps (0 until it has two).
    period: f64,
    /// `newest` came from the device's live feed, not from the latest
    /// sample fetched at its opening: the next stamp minus it is a step.
    live: bool,
    /// It missed a round's wait: not waited for until it publishes again.
    lagging: bool,
    /// The client opened the device and it had published once at most:
    /// its next sample is waited for (see [`Queue::expect`]).
    expected: bool,
    /// When the client opened the device, until this kind's second live
    /// sample (its live feed has begun then): its wait runs to [`OPEN_WAIT`]
    /// after this.
    opened: Option<Instant>,
}

/// The subtype of an opened device's pace before its first sample says
/// which kinds it publishes.
const ANY_SUBTYPE: u8 = u8::MAX;

impl Pace {
    /// Whether its sample for `t` should be on its way: its next stamp,
    /// by its pace, is at most `t`. One far behind `t` (stopped, or on
    /// another clock) is not waited for.
    fn due(&self, t: f64) -> bool {
        let p = self.period;
        if self.lagging {
            return false;
        }
        if p <= 0.0 {
            // An opened device with no pace yet: due until its first
            // sample, then at any newer step until its second.
            return self.expected && (self.sig.2 == ANY_SUBTYPE || self.newest < t);
        }
        self.newest + p <= t + 0.05 * p && t - self.newest < 3.0 * p
    }
}

/// One client's queue.
#[derive(Debug)]
pub struct Queue {
    items: VecDeque<Out>,
    /// How many of `items` are responses (never dropped, so counted: the
    /// bridge reads no more of a client's requests while too many wait).
    answers: usize,
    rules: Vec<Rule>,
    maxlen: usize,
    pull: bool,
    data_requested: bool,
    /// The pace of each kind of data that came, in arrival order.
    paces: Vec<Pace>,
    /// The newest stamp the last PULL round carried.
    round_stamp: f64,
    /// This round delivered data of a new step (see [`Queue::new_step`]):
    /// it may end.
    fresh: bool,
    /// When this round began waiting for due data (it had a new step),
    /// and the newest stamp then.
    waiting_since: Option<(Instant, f64)>,
    /// Until when a round waits for a new step or for due data.
    waiting: Option<Instant>,
    dropped: u32,
    dropped_total: u64,
    /// The stamp of the last data message written, by interface, index
    /// and subtype: a replace rule's step already delivered (kept only
    /// while a rule replaces).
    written: Vec<((u32, u32, u8), f64)>,
    /// Some rule replaces: [`Queue::written`] is kept.
    replacing: bool,
}

impl Queue {
    /// An empty queue in PUSH mode (Player's default) holding at most
    /// `maxlen` data messages.
    pub fn new(maxlen: usize) -> Queue {
        Queue {
            items: VecDeque::new(),
            answers: 0,
            rules: Vec::new(),
            maxlen,
            pull: false,
            data_requested: false,
            paces: Vec::new(),
            round_stamp: f64::NEG_INFINITY,
            fresh: false,
            waiting_since: None,
            waiting: None,
            dropped: 0,
            dropped_total: 0,
            written: Vec::new(),
            replacing: false,
        }
    }

    /// PUSH (`false`) or PULL (`true`).
    pub fn set_pull(&mut self, pull: bool) {
        self.pull = pull;
    }

    /// Whether the client reads in PULL mode.
    pub fn pull(&self) -> bool {
        self.pull
    }

    /// Adds a rule, or changes the action of an existing rule with the same
    /// fields (as Player's `AddReplaceRule`); `false`, adding nothing, when
    /// the client already has [`MAX_RULES`] rules.
    pub fn add_rule(&mut self, rule: Rule) -> bool {
        let same = |r: &&mut Rule| {
            (r.interf, r.index, r.kind, r.subtype)
                == (rule.interf, rule.index, rule.kind, rule.subtype)
        };
        if let Some(r) = self.rules.iter_mut().find(same) {
            r.replace = rule.replace;
        } else if self.rules.len() < MAX_RULES {
            self.rules.push(rule);
        } else {
            return false;
        }
        self.replacing = self.rules.iter().any(|r| r.replace == Replace::Replace);
        true
    }

    /// Responses waiting to be sent.
    pub fn answers(&self) -> usize {
        self.answers
    }

    /// The client opened a device at `now`: from the next PULL round on, a
    /// round waits for its data before it ends, its first sample and the
    /// one after, before the device's own pace is known, as Player's rounds
    /// after a subscription carried every opened device. It waits up to
    /// [`OPEN_WAIT`] from `now` (or [`ROUND_WAIT`], if longer), while the
    /// new subscription reaches the device's driver.
    pub fn expect(&mut self, interf: u32, index: u32, now: Instant) {
        if !self
            .paces
            .iter()
            .any(|p| (p.sig.0, p.sig.1) == (interf, index))
        {
            self.paces.push(Pace {
                sig: (interf, index, ANY_SUBTYPE),
                newest: f64::NEG_INFINITY,
                period: 0.0,
                live: false,
                lagging: false,
                expected: true,
                opened: Some(now),
            });
        }
    }

    /// The client closed a device: its pace no longer holds rounds back.
    pub fn forget(&mut self, interf: u32, index: u32) {
        self.paces.retain(|p| (p.sig.0, p.sig.1) != (interf, index));
        self.written.retain(|w| (w.0 .0, w.0 .1) != (interf, index));
    }

    /// When a PULL round waiting for due devices gives up on them: the
    /// queue's owner calls [`Queue::pop`] again then.
    pub fn deadline(&self) -> Option<Instant> {
        self.waiting
    }

    /// Counts `n` data messages that were dropped before they reached the
    /// queue, as if it had been full.
    pub fn overflowed(&mut self, n: u64) {
        self.dropped = self
            .dropped
            .saturating_add(u32::try_from(n).unwrap_or(u32::MAX));
        self.dropped_total += n;
    }

    /// Messages dropped because the queue was full, since the queue was made.
    pub fn dropped_total(&self) -> u64 {
        self.dropped_total
    }

    /// Messages waiting.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Queues a message under the replace rules and the length limit.
    pub fn push(&mut self, m: Out) {
        self.enqueue(m, true);
    }

    /// Queues the latest sample a device's driver kept, fetched as the
    /// client opened (or closed) it, as [`Queue::push`] does. Its stamp is
    /// not a step of the device's pace: the live feed may begin several
    /// steps after it, and a pace from that gap would let rounds end
    /// without the device.
    pub fn push_latest(&mut self, m: Out) {
        self.enqueue(m, false);
    }

    fn enqueue(&mut self, m: Out, live: bool) {
        // Paces matter to PULL rounds only (an opened device stays
        // expected until a PULL round sees its data).
        if self.pull && m.kind == wire::DATA {
            self.paced(&m, live);
        }
        let op = self
            .rules
            .iter()
            .find(|r| r.matches(&m))
            .map_or(Replace::Accept, |r| r.replace);
        match op {
            Replace::Ignore => return,
            Replace::Accept
                if matches!(m.kind, wire::DATA | wire::CMD) && self.items.len() >= self.maxlen =>
            {
                self.dropped = self.dropped.saturating_add(1);
                self.dropped_total += 1;
                return;
            }
            Replace::Replace => {
                if let Some(i) = self.items.iter().rposition(|o| o.same_signature(&m)) {
                    if self.items.remove(i).is_some_and(|o| o.is_response()) {
                        self.answers -= 1;
                    }
                } else if m.kind == wire::DATA && self.written_stamp(&m) == Some(m.stamp) {
                    // A second message of a step already written (Stage's
                    // ranger, so rangertolaser, sends two): Player, which
                    // writes its queues once per pass, replaces the first
                    // before it goes out; here the first went out.
                    return;
                }
            }
            Replace::Accept => {}
        }
        if m.is_response() {
            self.answers += 1;
        }
        self.items.push_back(m);
    }

    /// The stamp of the last data message written of `m`'s kind.
    fn written_stamp(&self, m: &Out) -> Option<f64> {
        let sig = (m.interf, m.index, m.subtype);
        self.written.iter().find(|w| w.0 == sig).map(|w| w.1)
    }

    /// Notes that data `m` was written.
    fn wrote(&mut self, m: &Out) {
        let sig = (m.interf, m.index, m.subtype);
        match self.written.iter_mut().find(|w| w.0 == sig) {
            Some(w) => w.1 = m.stamp,
            None => self.written.push((sig, m.stamp)),
        }
    }

    /// Notes a data sample's stamp in its pace (dropped or not: it came,
    /// so the round need not wait for it); `live` when it came from the
    /// device's feed.
    fn paced(&mut self, m: &Out, live: bool) {
        let sig = (m.interf, m.index, m.subtype);
        match self.paces.iter_mut().find(|p| p.sig == sig) {
            Some(p) => {
                if m.stamp > p.newest {
                    if p.live && live {
                        p.period = m.stamp - p.newest;
                        p.opened = None;
                    }
                    p.newest = m.stamp;
                    p.live = live;
                }
                p.lagging = false;
            }
            None => {
                // An opened device's first kind takes its place; the other
                // kinds of its first samples (a ranger's intensities after
                // its ranges) are expected as the first is.
                let any = |p: &Pace| p.sig == (m.interf, m.index, ANY_SUBTYPE);
                let sibling = |p: &&Pace| {
                    (p.sig.0, p.sig.1) == (m.interf, m.index) && p.expected && p.period <= 0.0
                };
                let (expected, opened) = match self.paces.iter().position(any) {
                    Some(i) => (true, self.paces.swap_remove(i).opened),
                    None => self
                        .paces
                        .iter()
                        .find(sibling)
                        .map_or((false, None), |p| (true, p.opened)),
                };
                self.paces.push(Pace {
                    sig,
                    newest: m.stamp,
                    period: 0.0,
                    live,
                    lagging: false,
                    expected,
                    opened,
                });
            }
        }
    }

    /// Whether data `m` belongs to a step after the last round's: newer
    /// than it carried, or of a kind whose stamps have not advanced (not
    /// paced, so nothing to wait for; an opened device's first sample is
    /// judged by its stamp).
    fn new_step(&self, m: &Out) -> bool {
        m.stamp > self.round_stamp
            || self
                .paces
                .iter()
                .find(|p| p.sig == (m.interf, m.index, m.subtype))
                .is_none_or(|p| p.period <= 0.0 && !p.expected)
    }

    /// Whether a round must still wait at `now`: for a new step, as long as
    /// it takes, while it has delivered no data or only late parts of the
    /// last round's (as a Player round with no data stays open); then for
    /// all data due at the newest stamp: at most [`QUIET_WAIT`] while no
    /// newer step comes, at most [`ROUND_WAIT`] once one has (for a device
    /// just opened, up to [`OPEN_WAIT`] after its opening). Data still due
    /// when that runs out is marked lagging.
    fn must_wait(&mut self, now: Instant) -> bool {
        if !self.fresh {
            return true;
        }
        let t = self.paces.iter().map(|p| p.newest).fold(f64::MIN, f64::max);
        let (since, at) = *self.waiting_since.get_or_insert((now, t));
        let round = since + if t > at { ROUND_WAIT } else { QUIET_WAIT };
        let until = self
            .paces
            .iter()
            .filter(|p| p.due(t))
            .map(|p| p.opened.map_or(round, |o| round.max(o + OPEN_WAIT)))
            .max();
        self.waiting = until;
        if let Some(until) = until {
            if now < until {
                return true;
            }
            for p in self.paces.iter_mut().filter(|p| p.due(t)) {
                tracing::debug!(
                    "a PULL round at {t:.3} s went without interface {} index {} subtype {}: \
                     its sample was due (newest {:.3} s, every {:.3} s) and did not come in time",
                    p.sig.0,
                    p.sig.1,
                    p.sig.2,
                    p.newest,
                    p.period
                );
                p.lagging = true;
            }
        }
        self.round_stamp = t;
        false
    }

    /// A client's `REQ DATA`: its ACK goes first, and a round opens.
    pub fn request_data(&mut self, ack: Out) {
        self.items.push_front(ack);
        self.answers += 1;
        self.data_requested = true;
        self.fresh = false;
        self.waiting_since = None;
        self.waiting = None;
    }

    /// The next message to send at `now`, if one may go.
    pub fn pop(&mut self, now: Instant) -> Option<Out> {
        // Between rounds a PULL client still gets answers (and what is
        // queued ahead of them) at once; the scan only runs then.
        let may_go = !self.pull || self.data_requested || self.answers > 0;
        if !self.items.is_empty() && may_go {
            let m = self.items.pop_front()?;
            if m.is_response() {
                self.answers -= 1;
            }
            if m.kind == wire::DATA {
                if self.replacing {
                    self.wrote(&m);
                }
                if self.pull && !self.data_requested {
                    // Data that went out ahead of an answer, between
                    // rounds: the client has that step, so the next
                    // round brings a newer one (Player's next pass).
                    self.round_stamp = self.round_stamp.max(m.stamp);
                }
            }
            if self.data_requested && m.kind == wire::DATA && !self.fresh && self.new_step(&m) {
                // Its wait for due data starts at the next `must_wait`
                // (nothing has set one since the request).
                self.fresh = true;
            }
            return Some(m);
        }
        // SYNCH once a new step went out (see `must_wait`).
        if self.pull && self.data_requested && !self.must_wait(now) {
            self.data_requested = false;
            self.waiting_since = None;
            self.waiting = None;
            let h = Header {
                interf: u32::from(PLAYER_CODE),
                kind: u32::from(wire::SYNCH),
                ..Header::default()
            };
            return Some(if self.dropped == 0 {
                Out::new(
                    Header {
                        subtype: u32::from(wire::player::SYNCH_OK),
                        ..h
                    },
                    &[],
                )
            } else {
                let n = std::mem::take(&mut self.dropped);
                Out::new(
                    Header {
                        subtype: u32::from(wire::player::SYNCH_OVERFLOW),
                        ..h
                    },
                    &n.to_be_bytes(),
                )
            });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(kind: u8, interf: u32, subtype: u8) -> Out {
        Out::new(
            Header {
                interf,
                kind: u32::from(kind),
                subtype: u32::from(subtype),
                ..Header::default()
            },
            &[],
        )
    }

    fn drain(q: &mut Queue) -> Vec<(u8, u32)> {
        drain_at(q, Instant::now())
    }

    /// What may go at `now`.
    fn drain_at(q: &mut Queue, now: Instant) -> Vec<(u8, u32)> {
        std::iter::from_fn(|| q.pop(now))
            .map(|m| (m.kind, m.interf))
            .collect()
    }

    fn data(interf: u32, stamp: f64) -> Out {
        Out::new(
            Header {
                interf,
                kind: u32::from(D),
                subtype: 1,
                timestamp: stamp,
                ..Header::default()
            },
            &[],
        )
    }

    /// A PULL queue that has seen position2d (4) and laser (6) data at
    /// 0.0 and 0.1 s, with no round open.
    fn paced_pull() -> Queue {
        let mut q = Queue::new(64);
        q.set_pull(true);
        for t in [0.0, 0.1] {
            q.push(data(4, t));
            q.push(data(6, t));
        }
        q.request_data(msg(A, 1, 4));
        drain(&mut q);
        q
    }

    /// A PULL queue whose client opened position2d (4) and laser (6) and
    /// asked for a round, before either published.
    fn opened_pull() -> Queue {
        let mut q = Queue::new(64);
        q.set_pull(true);
        q.expect(4, 0, Instant::now());
        q.expect(6, 0, Instant::now());
        q.request_data(msg(A, 1, 4));
        q
    }

    /// Data of one kind (`subtype`) of device `interf`:`index`.
    fn data_of(interf: u32, index: u32, subtype: u8, stamp: f64) -> Out {
        Out::new(
            Header {
                interf,
                index,
                kind: u32::from(D),
                subtype: u32::from(subtype),
                timestamp: stamp,
                ..Header::default()
            },
            &[],
        )
    }

    const D: u8 = wire::DATA;
    const A: u8 = wire::RESP_ACK;
    const S: u8 = wire::SYNCH;

    #[test]
    fn push_mode_sends_everything_in_order() {
        let mut q = Queue::new(8);
        q.push(msg(D, 4, 1));
        q.push(msg(A, 1, 3));
        q.push(msg(D, 6, 1));
        assert_eq!(drain(&mut q), [(D, 4), (A, 1), (D, 6)]);
    }

    #[test]
    fn pull_round_is_ack_data_synch_and_waits_for_data() {
        let mut q = Queue::new(8);
        q.set_pull(true);
        q.push(msg(D, 4, 1));
        assert!(
            q.pop(Instant::now()).is_none(),
            "data waits for a request in PULL mode"
        );
        q.request_data(msg(A, 1, 4));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4), (S, 1)]);
        // An empty round: the ACK goes, no SYNCH until data arrives.
        q.request_data(msg(A, 1, 4));
        assert_eq!(drain(&mut q), [(A, 1)]);
        q.push(msg(D, 6, 1));
        assert_eq!(drain(&mut q), [(D, 6), (S, 1)]);
    }

    #[test]
    fn a_response_flushes_the_data_ahead_of_it_without_synch() {
        let mut q = Queue::new(8);
        q.set_pull(true);
        q.push(msg(D, 4, 1));
        q.push(msg(A, 1, 3));
        q.push(msg(D, 6, 1));
        assert_eq!(drain(&mut q), [(D, 4), (A, 1)]);
        assert_eq!(q.len(), 1);
    }

    /// A rule that replaces every device's data (libplayerc's advice).
    fn replace_data() -> Rule {
        Rule {
            interf: -1,
            index: -1,
            kind: i32::from(D),
            subtype: -1,
            replace: Replace::Replace,
        }
    }

    #[test]
    fn replace_rule_keeps_only_the_newest_of_a_signature() {
        let mut q = Queue::new(8);
        q.set_pull(true);
        q.add_rule(replace_data());
        for _ in 0..5 {
            q.push(msg(D, 4, 1));
            q.push(msg(D, 6, 1));
        }
        assert_eq!(q.len(), 2);
        q.add_rule(Rule {
            interf: 6,
            index: -1,
            kind: -1,
            subtype: -1,
            replace: Replace::Ignore,
        });
        // The first rule still matches laser data first: replaced, not ignored.
        q.push(msg(D, 6, 1));
        assert_eq!(q.len(), 2);
    }

    #[test]
    fn a_full_queue_drops_data_not_responses_and_reports_overflow() {
        let mut q = Queue::new(2);
        q.set_pull(true);
        for _ in 0..5 {
            q.push(msg(D, 4, 1));
        }
        q.push(msg(A, 4, 1));
        assert_eq!(q.len(), 3);
        assert_eq!(q.dropped_total(), 3);
        drain(&mut q);
        q.push(msg(D, 4, 1));
        q.request_data(msg(A, 1, 4));
        let out: Vec<Out> = std::iter::from_fn(|| q.pop(Instant::now())).collect();
        let synch = out.last().unwrap();
        assert_eq!(synch.subtype, wire::player::SYNCH_OVERFLOW);
        assert_eq!(&synch.bytes[40..], &3u32.to_be_bytes());
    }

    #[test]
    fn rounds_after_opening_wait_for_every_opened_device_until_its_pace_is_known() {
        let mut q = opened_pull();
        q.push(data(4, 0.1));
        // The laser has not published yet: the round waits for it.
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)]);
        q.push(data(6, 0.1));
        assert_eq!(drain(&mut q), [(D, 6), (S, 1)]);
        // One sample of each so far, so no pace: both are due at a newer step.
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.2));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)]);
        q.push(data(6, 0.2));
        assert_eq!(drain(&mut q), [(D, 6), (S, 1)]);
    }

    #[test]
    fn an_opened_device_that_never_publishes_holds_one_round_back_once() {
        let opened = Instant::now();
        let mut q = opened_pull();
        q.push(data(4, 0.1));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)]);
        // Its subscription may still be on its way: a round's wait is not
        // enough to give it up.
        let late = Instant::now() + ROUND_WAIT;
        assert!(
            q.pop(late).is_none(),
            "a device just opened is given longer"
        );
        let until = q.deadline().expect("waiting for the laser");
        assert!(until >= opened + OPEN_WAIT, "{:?}", until - opened);
        assert_eq!(q.pop(until).map(|m| m.kind), Some(S));
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.2));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4), (S, 1)]);
        // Closed, it is forgotten; opened again, it is expected again,
        // and long after its opening a round waits for it while no newer
        // step comes, then a round's wait.
        q.forget(6, 0);
        let long_ago = Instant::now().checked_sub(2 * OPEN_WAIT).expect("uptime");
        q.expect(6, 0, long_ago);
        q.request_data(msg(A, 1, 4));
        let start = Instant::now();
        q.push(data(4, 0.3));
        assert_eq!(drain_at(&mut q, start), [(A, 1), (D, 4)]);
        let until = q.deadline().expect("waiting for the laser");
        assert_eq!(until, start + QUIET_WAIT);
        // A newer step: the laser is late, and gets a round's wait.
        q.push(data(4, 0.4));
        assert_eq!(drain_at(&mut q, start), [(D, 4)]);
        let until = q.deadline().expect("waiting for the laser");
        assert_eq!(until, start + ROUND_WAIT);
        assert_eq!(q.pop(until).map(|m| m.kind), Some(S));
    }

    #[test]
    fn a_round_waits_longer_for_a_late_device_while_no_newer_step_comes() {
        // Position and laser publish each step; this step's laser is late.
        let mut q = paced_pull();
        q.request_data(msg(A, 1, 4));
        let start = Instant::now();
        q.push(data(4, 0.2));
        assert_eq!(drain_at(&mut q, start), [(A, 1), (D, 4)]);
        // Past a round's wait, with no newer step, the step may still be
        // on its way: the round still waits.
        assert!(q.pop(start + 2 * ROUND_WAIT).is_none());
        assert_eq!(q.deadline(), Some(start + QUIET_WAIT));
        // The laser comes: the round carries it and ends.
        q.push(data(6, 0.2));
        assert_eq!(drain_at(&mut q, start + 2 * ROUND_WAIT), [(D, 6), (S, 1)]);
    }

    #[test]
    fn the_gap_from_a_latest_sample_to_a_late_live_feed_is_not_a_pace() {
        // Opened at 0.1 s and a round asked for: both devices' latest
        // samples come first; the laser's live feed starts two steps later
        // (a loaded CI run).
        let mut q = opened_pull();
        q.push_latest(data(4, 0.1));
        q.push_latest(data(6, 0.1));
        for m in [data(4, 0.2), data(4, 0.3), data(6, 0.3)] {
            q.push(m);
        }
        assert_eq!(
            drain(&mut q),
            [(A, 1), (D, 4), (D, 6), (D, 4), (D, 4), (D, 6), (S, 1)]
        );
        // The laser steps every 0.1 s, not 0.2 s: the next round waits for
        // it (it went without it, as a laser 0.2 s apart is not due at 0.4).
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.4));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)]);
        assert!(q.deadline().is_some(), "the round waits for the laser");
        q.push(data(6, 0.4));
        assert_eq!(drain(&mut q), [(D, 6), (S, 1)]);
    }

    #[test]
    fn the_late_first_samples_of_an_opened_ranger_make_no_round_of_their_own() {
        // A ranger publishes two kinds a step, ranges (1) and intensities
        // (3). The client opens it and position2d, which has a latest
        // sample; the ranger's feed starts late, after two rounds.
        let mut q = Queue::new(64);
        q.set_pull(true);
        q.expect(4, 0, Instant::now());
        q.expect(62, 1, Instant::now());
        q.push(data_of(4, 0, 1, 0.0));
        q.request_data(msg(A, 1, 4));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)]);
        let until = q.deadline().expect("waiting for the ranger");
        assert_eq!(q.pop(until).map(|m| m.kind), Some(S));
        // Given up, it is not waited for until it publishes.
        q.request_data(msg(A, 1, 4));
        q.push(data_of(4, 0, 1, 0.1));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4), (S, 1)]);
        // Its first samples, of 0.1, are late parts of the last round, both
        // kinds: the round waits for the next step.
        q.request_data(msg(A, 1, 4));
        q.push(data_of(62, 1, 1, 0.1));
        q.push(data_of(62, 1, 3, 0.1));
        assert_eq!(drain(&mut q), [(A, 1), (D, 62), (D, 62)]);
        for m in [data_of(4, 0, 1, 0.2), data_of(62, 1, 1, 0.2)] {
            q.push(m);
        }
        assert_eq!(drain(&mut q), [(D, 4), (D, 62)], "the intensities are due");
        q.push(data_of(62, 1, 3, 0.2));
        assert_eq!(drain(&mut q), [(D, 62), (S, 1)]);
    }

    #[test]
    fn a_pull_round_waits_for_every_device_due_at_its_newest_stamp() {
        let mut q = paced_pull();
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.2));
        // The laser's sample for 0.2 is due: no SYNCH yet.
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)]);
        assert!(q.deadline().is_some());
        q.push(data(6, 0.2));
        assert_eq!(drain(&mut q), [(D, 6), (S, 1)]);
        assert!(q.deadline().is_none());
    }

    #[test]
    fn a_device_that_misses_the_wait_is_not_waited_for_until_it_publishes() {
        let mut q = paced_pull();
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.2));
        drain(&mut q);
        let until = q.deadline().expect("waiting for the laser");
        assert_eq!(q.pop(until).map(|m| m.kind), Some(S), "the wait is bounded");
        // The laser is lagging now: the next round does not wait for it.
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.3));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4), (S, 1)]);
        // It publishes again: waited for again.
        q.request_data(msg(A, 1, 4));
        q.push(data(6, 0.3));
        q.push(data(4, 0.4));
        q.push(data(6, 0.4));
        q.push(data(4, 0.5));
        assert_eq!(drain(&mut q), [(A, 1), (D, 6), (D, 4), (D, 6), (D, 4)]);
        q.push(data(6, 0.5));
        assert_eq!(drain(&mut q), [(D, 6), (S, 1)]);
    }

    #[test]
    fn a_slower_device_is_waited_for_only_at_its_own_pace_and_a_closed_one_never() {
        let mut q = Queue::new(64);
        q.set_pull(true);
        // Position2d every 0.1 s, a ranger (5) every 0.5 s.
        for t in [0.0, 0.5] {
            q.push(data(5, t));
        }
        for t in [0.4, 0.5] {
            q.push(data(4, t));
        }
        q.request_data(msg(A, 1, 4));
        drain(&mut q);
        for t in [0.6, 0.7, 0.8, 0.9] {
            q.request_data(msg(A, 1, 4));
            q.push(data(4, t));
            assert_eq!(drain(&mut q), [(A, 1), (D, 4), (S, 1)], "at {t}");
        }
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 1.0));
        assert_eq!(drain(&mut q), [(A, 1), (D, 4)], "the ranger is due at 1.0");
        q.forget(5, 0);
        assert_eq!(
            drain(&mut q),
            [(S, 1)],
            "a closed device holds nothing back"
        );
    }

    #[test]
    fn a_late_part_of_the_last_step_does_not_make_a_round_of_its_own() {
        let mut q = paced_pull();
        q.request_data(msg(A, 1, 4));
        q.push(data(4, 0.2));
        drain(&mut q);
        let until = q.deadline().expect("waiting for the laser");
        assert_eq!(q.pop(until).map(|m| m.kind), Some(S));
        // The laser's scan for 0.2 comes after that round: the next round
        // carries it, then waits for the step after.
        q.request_data(msg(A, 1, 4));
        q.push(data(6, 0.2));
        assert_eq!(
            drain(&mut q),
            [(A, 1), (D, 6)],
            "no round of a late scan alone"
        );
        q.push(data(4, 0.3));
        q.push(data(6, 0.3));
        assert_eq!(drain(&mut q), [(D, 4), (D, 6), (S, 1)]);
        // A round of late data waits for the next step, however long.
        q.request_data(msg(A, 1, 4));
        q.push(data(6, 0.3));
        assert_eq!(drain(&mut q), [(A, 1), (D, 6)]);
        assert_eq!(q.deadline(), None);
        q.push(data(4, 0.4));
        q.push(data(6, 0.4));
        assert_eq!(drain(&mut q), [(D, 4), (D, 6), (S, 1)]);
    }

    /// Player with Stage: rangertolaser publishes a laser scan per ranger
    /// message, two per step with one stamp, and Player writes a client's
    /// queue once per pass, so a replace rule leaves one scan a step (287
    /// in 28.6 simulated s). Here the first of the two may be written
    /// before the second comes; the second is then dropped.
    #[test]
    fn a_replace_rule_leaves_one_message_of_a_kind_a_step() {
        let mut q = Queue::new(8);
        q.add_rule(replace_data());
        for t in [0.1, 0.2] {
            q.push(data(6, t));
            assert_eq!(drain(&mut q), [(D, 6)]);
            q.push(data(6, t));
            assert_eq!(drain(&mut q), [], "the second scan of {t}");
        }
        // Another kind of the same step still goes out.
        q.push(data_of(6, 0, 2, 0.2));
        assert_eq!(drain(&mut q), [(D, 6)]);
        // Closed and opened again: its steps start afresh.
        q.forget(6, 0);
        q.push(data(6, 0.2));
        assert_eq!(drain(&mut q), [(D, 6)]);
        // With no rule, as from Player, both copies go out.
        let mut q = Queue::new(8);
        for _ in 0..2 {
            q.push(data(6, 0.1));
        }
        assert_eq!(drain(&mut q), [(D, 6), (D, 6)]);
    }

    /// A client opens position2d, then the laser, and reads as libplayerc
    /// does: position2d's data that went out ahead of the laser's answer
    /// is a step the client has, so its next round (its second read)
    /// brings a whole newer step, as Player's next pass does, not the
    /// laser's sample of that same step alone.
    #[test]
    fn a_round_after_data_went_out_with_an_answer_brings_a_newer_step() {
        let mut q = Queue::new(64);
        q.set_pull(true);
        q.expect(4, 0, Instant::now());
        q.push(data(4, 0.1));
        q.push(msg(A, 1, 4));
        assert_eq!(drain(&mut q), [(D, 4), (A, 1)]);
        q.expect(6, 0, Instant::now());
        q.push(msg(A, 1, 6));
        // The laser's latest, sent on opening, as the bridge does.
        q.push(data(6, 0.1));
        assert_eq!(drain(&mut q), [(A, 1)]);
        q.request_data(msg(A, 1, 4));
        assert_eq!(
            drain(&mut q),
            [(A, 1), (D, 6)],
            "no SYNCH on a step the client has"
        );
        q.push(data(4, 0.2));
        q.push(data(6, 0.2));
        assert_eq!(drain(&mut q), [(D, 4), (D, 6), (S, 1)]);
    }
}
