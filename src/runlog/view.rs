//! One unit of a batch's log, read as the log of that unit alone: what
//! `replay`, `export`, `allan`, `calibrate` and `diagnose` read with
//! `--unit SERIAL`.
//!
//! A batch logs its first unit on the single-unit topics and each other
//! unit under `/slots/NAME/` (`runlog::schema::slot_topic`), its result as
//! the metadata record `result/NAME` and its report as the attachment
//! `report-SERIAL.json`. The view hands a reader the unit's own items
//! under the single-unit names: its topics, its `result`, its report, the
//! `run` record as its report names it (`RunMeta::for_unit`) and, at the
//! end of each record, its own link figures; the other units' items are
//! left out. The shared channels (chamber, events, steps, supply) pass as
//! they are.

use std::collections::BTreeMap;
use std::path::Path;

use super::meta::RunMeta;
use std::ops::ControlFlow;

use super::reader::{self, Item, ReadError, ReadSummary, Stop};
use super::schema::{
    REPORT_ATTACHMENT, RESULT_META, RUN_META, SLOT_TOPICS, StepEvent, slot_topic, topics,
};

/// Read `path` as the log of unit `serial` alone (none: every item as
/// written), calling `f` for every item of the unit in file order. A log
/// without that unit stops the read, refused with a message naming the
/// units it holds.
pub fn read_unit(
    path: &Path,
    serial: Option<&str>,
    mut f: impl FnMut(Item<'_>) -> ControlFlow<Stop>,
) -> Result<ReadSummary, ReadError> {
    let Some(serial) = serial else {
        return reader::read(path, f);
    };
    read_units(path, &[serial.to_owned()], |_, item| f(item))
}

/// Read `path` once as the logs of each unit of `serials` alone: `f(k,
/// item)` gets every item of unit `serials[k]` as [`read_unit`] would
/// give it (the units in turn, item by item), so a batch's units are had
/// from one pass over its chunks. A log without one of them stops the
/// read with a message naming the units it holds.
pub fn read_units(
    path: &Path,
    serials: &[String],
    mut f: impl FnMut(usize, Item<'_>) -> ControlFlow<Stop>,
) -> Result<ReadSummary, ReadError> {
    let mut units: Vec<Unit> = Vec::new();
    reader::read(path, |item| match item {
        Item::Meta { name, entries } if name == RUN_META => {
            let meta = match RunMeta::from_entries(entries) {
                Ok(m) => m,
                Err(e) => return ControlFlow::Break(Stop::Refused(e.to_string())),
            };
            for (i, serial) in serials.iter().enumerate() {
                let Some(k) = meta.units.iter().position(|u| &u.serial == serial) else {
                    let held: Vec<&str> = meta.units.iter().map(|u| u.serial.as_str()).collect();
                    return ControlFlow::Break(Stop::Refused(format!(
                        "the log holds no unit {serial} (its units: {})",
                        held.join(", ")
                    )));
                };
                units.push(Unit::new(k, &meta.units[k].slot, serial));
                let entries = meta.for_unit(k).to_entries();
                f(
                    i,
                    Item::Meta {
                        name,
                        entries: &entries,
                    },
                )?;
            }
            ControlFlow::Continue(())
        }
        item if units.is_empty() => (0..serials.len()).try_for_each(|i| f(i, again(&item))),
        item => units
            .iter()
            .enumerate()
            .try_for_each(|(i, u)| u.pass(again(&item), &mut |it| f(i, it))),
    })
}

/// The same item again (its parts are borrowed: a view hands one item to
/// each unit it shows).
fn again<'a>(item: &Item<'a>) -> Item<'a> {
    match *item {
        Item::Meta { name, entries } => Item::Meta { name, entries },
        Item::Message {
            topic,
            channel,
            sequence,
            log_time_ns,
            publish_time_ns,
            data,
        } => Item::Message {
            topic,
            channel,
            sequence,
            log_time_ns,
            publish_time_ns,
            data,
        },
        Item::Attachment {
            name,
            media_type,
            log_time_ns,
            data,
        } => Item::Attachment {
            name,
            media_type,
            log_time_ns,
            data,
        },
    }
}

/// The unit a view shows.
struct Unit {
    /// Its place in the run's units (0: the first).
    k: usize,
    /// `/slots/NAME` (none for the first unit).
    prefix: Option<String>,
    /// `result/NAME`.
    result: String,
    /// `report-SERIAL.json`.
    report: String,
}

impl Unit {
    fn new(k: usize, slot: &str, serial: &str) -> Self {
        Self {
            k,
            prefix: (k > 0).then(|| slot_topic(slot, "")),
            result: format!("{RESULT_META}/{slot}"),
            report: format!("{}.json", crate::unit::report_name(serial)),
        }
    }

    /// Hand `item` to `f` under its single-unit name when it is this
    /// unit's or shared; leave it out when it is another unit's.
    fn pass(
        &self,
        item: Item<'_>,
        f: &mut impl FnMut(Item<'_>) -> ControlFlow<Stop>,
    ) -> ControlFlow<Stop> {
        let first = self.k == 0;
        match item {
            Item::Meta { name, entries } => {
                if (first && name == RESULT_META) || (!first && name == self.result) {
                    f(Item::Meta {
                        name: RESULT_META,
                        entries,
                    })
                } else if name.starts_with(RESULT_META) {
                    ControlFlow::Continue(())
                } else {
                    f(Item::Meta { name, entries })
                }
            }
            Item::Attachment {
                name,
                media_type,
                log_time_ns,
                data,
            } => {
                let mine = if first {
                    name == REPORT_ATTACHMENT
                } else {
                    name == self.report
                };
                if mine || !name.starts_with("report") {
                    f(Item::Attachment {
                        name: if mine { REPORT_ATTACHMENT } else { name },
                        media_type,
                        log_time_ns,
                        data,
                    })
                } else {
                    ControlFlow::Continue(())
                }
            }
            Item::Message {
                topic,
                channel,
                sequence,
                log_time_ns,
                publish_time_ns,
                data,
            } => {
                let own = self
                    .prefix
                    .as_deref()
                    .and_then(|p| topic.strip_prefix(p))
                    .filter(|t| SLOT_TOPICS.contains(t));
                let topic = match own {
                    Some(t) => t,
                    // Another unit's, or (for a unit after the first) the
                    // first unit's.
                    None if topic.starts_with("/slots/") => return ControlFlow::Continue(()),
                    None if !first && SLOT_TOPICS.contains(&topic) => {
                        return ControlFlow::Continue(());
                    }
                    None => topic,
                };
                let steps;
                let data = if !first && topic == topics::STEPS {
                    steps = match self.own_link(data) {
                        Ok(s) => s,
                        Err(why) => return ControlFlow::Break(Stop::Refused(why)),
                    };
                    &steps[..]
                } else {
                    data
                };
                f(Item::Message {
                    topic,
                    channel,
                    sequence,
                    log_time_ns,
                    publish_time_ns,
                    data,
                })
            }
        }
    }

    /// A `/steps` event with this unit's link figures as its `link`.
    fn own_link(&self, data: &[u8]) -> Result<Vec<u8>, String> {
        let mut e: StepEvent =
            serde_json::from_slice(data).map_err(|e| format!("{}: {e}", topics::STEPS))?;
        if e.link.is_some() {
            e.link = e.slot_links.get(self.k - 1).copied();
        }
        e.slot_links.clear();
        serde_json::to_vec(&e).map_err(|e| format!("{}: {e}", topics::STEPS))
    }
}

/// The units a log's `run` record names, `(slot, serial)` in order; empty
/// when it has none readable.
pub fn units_of(entries: &BTreeMap<String, String>) -> Vec<(String, String)> {
    RunMeta::from_entries(entries)
        .map(|m| m.units.into_iter().map(|u| (u.slot, u.serial)).collect())
        .unwrap_or_default()
}

/// The units the log at `path` holds, `(slot, serial)` in order, from its
/// `run` record (read first; the rest of the file is not read).
pub fn log_units(path: &Path) -> Result<Vec<(String, String)>, ReadError> {
    let mut units = Vec::new();
    reader::read(path, |item| match item {
        Item::Meta { name, entries } if name == RUN_META => {
            units = units_of(entries);
            ControlFlow::Break(Stop::Enough)
        }
        _ => ControlFlow::Continue(()),
    })?;
    Ok(units)
}

/// Whether `units` ([`log_units`]) are a batch's: in named slots (a bench
/// with `[[slots]]`, even with one unit in it).
pub fn is_batch(units: &[(String, String)]) -> bool {
    units.iter().any(|(slot, _)| !slot.is_empty())
}
