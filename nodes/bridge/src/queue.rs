//! A client's outgoing queue, with Player's `MessageQueue` semantics.
//!
//! - PUSH mode: everything goes out in order.
//! - PULL mode: data waits until the client asks (`REQ DATA`); the ACK goes
//!   to the front, then everything queued, then `SYNCH` — only if some data
//!   was delivered, otherwise the round stays open until data comes.
//!   A response queued outside a round flushes everything ahead of it.
//! - Replace rules (first match wins, -1 = any): ACCEPT, REPLACE the older
//!   message of the same device/type/subtype, or IGNORE. Default: accept.
//! - Bounded: DATA and CMD beyond `maxlen` are dropped and counted; in PULL
//!   mode the round then ends with `SYNCH OVERFLOW` carrying the count.
//!   Responses are never dropped (a client waits for them).

use std::collections::VecDeque;
use std::sync::Arc;

use crate::wire::{self, Header, PLAYER_CODE, RESP_ACK, RESP_NACK};

/// Player's `PLAYER_MSGQUEUE_DEFAULT_MAXLEN`.
pub const DEFAULT_MAXLEN: usize = 1024;

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

/// One client's queue.
#[derive(Debug)]
pub struct Queue {
    items: VecDeque<Out>,
    rules: Vec<Rule>,
    maxlen: usize,
    pull: bool,
    data_requested: bool,
    data_delivered: bool,
    dropped: u32,
    dropped_total: u64,
}

impl Queue {
    /// An empty queue in PUSH mode (Player's default) holding at most
    /// `maxlen` data messages.
    pub fn new(maxlen: usize) -> Queue {
        Queue {
            items: VecDeque::new(),
            rules: Vec::new(),
            maxlen,
            pull: false,
            data_requested: false,
            data_delivered: false,
            dropped: 0,
            dropped_total: 0,
        }
    }

    /// PUSH (`false`) or PULL (`true`).
    pub fn set_pull(&mut self, pull: bool) {
        self.pull = pull;
    }

    /// Adds a rule, or changes the action of an existing rule with the same fields.
    pub fn add_rule(&mut self, rule: Rule) {
        let same = |r: &&mut Rule| {
            (r.interf, r.index, r.kind, r.subtype)
                == (rule.interf, rule.index, rule.kind, rule.subtype)
        };
        match self.rules.iter_mut().find(same) {
            Some(r) => r.replace = rule.replace,
            None => self.rules.push(rule),
        }
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
                    self.items.remove(i);
                }
            }
            Replace::Accept => {}
        }
        self.items.push_back(m);
    }

    /// A client's `REQ DATA`: its ACK goes first, and a round opens.
    pub fn request_data(&mut self, ack: Out) {
        self.items.push_front(ack);
        self.data_requested = true;
        self.data_delivered = false;
    }

    /// The next message to send, if one may go now.
    pub fn pop(&mut self) -> Option<Out> {
        // Between rounds a PULL client still gets answers (and what is
        // queued ahead of them) at once; the scan only runs then.
        let may_go = !self.pull || self.data_requested || self.items.iter().any(Out::is_response);
        if !self.items.is_empty() && may_go {
            let m = self.items.pop_front()?;
            if self.data_requested && m.kind == wire::DATA {
                self.data_delivered = true;
            }
            return Some(m);
        }
        if self.pull && self.data_requested && self.data_delivered {
            self.data_requested = false;
            self.data_delivered = false;
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
        std::iter::from_fn(|| q.pop())
            .map(|m| (m.kind, m.interf))
            .collect()
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
        assert!(q.pop().is_none(), "data waits for a request in PULL mode");
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

    #[test]
    fn replace_rule_keeps_only_the_newest_of_a_signature() {
        let mut q = Queue::new(8);
        q.set_pull(true);
        q.add_rule(Rule {
            interf: -1,
            index: -1,
            kind: i32::from(D),
            subtype: -1,
            replace: Replace::Replace,
        });
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
        let out: Vec<Out> = std::iter::from_fn(|| q.pop()).collect();
        let synch = out.last().unwrap();
        assert_eq!(synch.subtype, wire::player::SYNCH_OVERFLOW);
        assert_eq!(&synch.bytes[40..], &3u32.to_be_bytes());
    }
}
