//! rosbag2's sqlite3 storage (`.db3`, rosbag2_storage_default_plugins): a `topics` table (id,
//! name, type, serialization_format) and a `messages` table (topic_id, timestamp in nanoseconds,
//! data), read with SQLite itself (the `rusqlite` crate) read-only, messages in timestamp order as
//! `ros2 bag play` takes them. A message longer than the bound is refused before its bytes are
//! read.

use super::StorageRecord;
use rusqlite::{Connection, OpenFlags};
use std::collections::BTreeMap;
use std::path::Path;

/// One `topics` row.
#[derive(Clone, Debug, PartialEq)]
pub struct DbTopic {
    pub id: i64,
    pub name: String,
    pub msg_type: String,
    pub encoding: String,
}

/// An open `.db3`, read-only.
pub struct Database {
    connection: Connection,
}

fn sql(e: rusqlite::Error) -> String {
    format!("not a readable rosbag2 database: {e}")
}

impl Database {
    pub fn open(path: &Path) -> Result<Self, String> {
        let flags = OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let connection = Connection::open_with_flags(path, flags).map_err(sql)?;
        Ok(Self { connection })
    }

    pub fn topics(&self) -> Result<Vec<DbTopic>, String> {
        let mut statement = self
            .connection
            .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
            .map_err(sql)?;
        let rows = statement
            .query_map([], |row| {
                Ok(DbTopic { id: row.get(0)?, name: row.get(1)?, msg_type: row.get(2)?, encoding: row.get(3)? })
            })
            .map_err(sql)?;
        rows.collect::<Result<_, _>>().map_err(sql)
    }

    /// Messages per topic id.
    pub fn counts(&self) -> Result<BTreeMap<i64, u64>, String> {
        let mut statement =
            self.connection.prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id").map_err(sql)?;
        let rows = statement.query_map([], |row| Ok((row.get::<_, i64>(0)?, row.get::<_, i64>(1)?))).map_err(sql)?;
        rows.map(|row| row.map(|(id, n)| (id, n.max(0) as u64))).collect::<Result<_, _>>().map_err(sql)
    }

    /// Hands `visit` each topic, then each message in timestamp order, until it returns false.
    pub fn read(
        &self,
        max_message_bytes: usize,
        visit: &mut dyn FnMut(StorageRecord) -> Result<bool, String>,
    ) -> Result<(), String> {
        for topic in self.topics()? {
            let Ok(id) = u32::try_from(topic.id) else {
                return Err(format!("topic {} has id {}, beyond what a topic id may be", topic.name, topic.id));
            };
            let record =
                StorageRecord::Topic { id, name: &topic.name, msg_type: &topic.msg_type, encoding: &topic.encoding };
            if !visit(record)? {
                return Ok(());
            }
        }
        let mut statement = self
            .connection
            .prepare("SELECT id, topic_id, timestamp, length(data), data FROM messages ORDER BY timestamp, id")
            .map_err(sql)?;
        let mut rows = statement.query([]).map_err(sql)?;
        while let Some(row) = rows.next().map_err(sql)? {
            let (id, topic, time, len): (i64, i64, i64, i64) = (
                row.get(0).map_err(sql)?,
                row.get(1).map_err(sql)?,
                row.get(2).map_err(sql)?,
                row.get(3).map_err(sql)?,
            );
            let time_nanos =
                u64::try_from(time).map_err(|_| format!("message {id}: timestamp {time} ns is before 1970"))?;
            let Ok(topic) = u32::try_from(topic) else {
                return Err(format!("message {id}: topic id {topic}, beyond what a topic id may be"));
            };
            if len < 0 || len as u64 > max_message_bytes as u64 {
                return Err(format!("message {id}: {len} bytes, at most {max_message_bytes} accepted"));
            }
            let data = match row.get_ref(4).map_err(sql)? {
                rusqlite::types::ValueRef::Blob(data) => data,
                rusqlite::types::ValueRef::Null => &[][..],
                _ => return Err(format!("message {id}: data is not a blob")),
            };
            if !visit(StorageRecord::Message { topic, time_nanos, data })? {
                return Ok(());
            }
        }
        Ok(())
    }
}
