//! The action batch (`wg/<run>/act`): the learner's answer to one
//! observation batch, one MiniGrid action byte per environment (README.md,
//! "The environment contract": 0 left, 1 right, 2 forward, 3 pickup,
//! 4 drop, 5 toggle, 6 done).
//!
//! Layout: user header [`ActHeader`], payload `[u8]` of exactly `N` bytes.

use bytemuck::{Pod, Zeroable};
#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

use crate::step::{check_len, check_run, check_version};
use crate::{Channel, MAX_ENVS, SCHEMA_VERSION, SchemaError};

/// Number of distinct actions (MiniGrid numbering, `0..NUM_ACTIONS`).
pub const NUM_ACTIONS: u8 = 7;

/// Header of an action batch (iceoryx2 user header of `wg/<run>/act`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("wg.ActHeader.v3"))]
#[repr(C)]
pub struct ActHeader {
    /// [`SCHEMA_VERSION`] of the writer.
    pub schema_version: u32,
    /// Environments in the batch (`N`).
    pub num_envs: u32,
    /// [`crate::service::RunName::id`] of the run.
    pub run_id: u64,
    /// `seq` of the observation batch these actions answer.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` time of `send()` in ns.
    pub send_time_ns: u64,
}

impl ActHeader {
    /// A header for `num_envs` environments in run `run_id`, answering `seq`.
    pub fn new(num_envs: u32, run_id: u64, seq: u64) -> ActHeader {
        ActHeader {
            schema_version: SCHEMA_VERSION,
            num_envs,
            run_id,
            seq,
            send_time_ns: 0,
        }
    }

    /// Checks version, run and batch size against what this process expects.
    pub fn check(&self, num_envs: u32, run_id: u64) -> Result<(), SchemaError> {
        check_version(Channel::Act, self.schema_version)?;
        check_run(Channel::Act, run_id, self.run_id)?;
        if self.num_envs != num_envs {
            return Err(SchemaError::BatchSize {
                channel: Channel::Act,
                expected: num_envs,
                wire: self.num_envs,
            });
        }
        Ok(())
    }
}

/// Checks a batch size against [`MAX_ENVS`].
#[cfg(feature = "ipc")]
pub(crate) fn check_num_envs(num_envs: usize) -> Result<u32, SchemaError> {
    crate::step::check_range(Channel::Act, "num_envs", num_envs, MAX_ENVS)?;
    Ok(num_envs as u32)
}

/// Read view of one action batch.
#[derive(Debug, Clone, Copy)]
pub struct ActBatch<'a> {
    /// The header.
    pub header: &'a ActHeader,
    /// `N` action bytes, environment `i` at index `i`.
    pub actions: &'a [u8],
}

impl<'a> ActBatch<'a> {
    /// Views `payload` after checking `header` against the expected batch
    /// size and run.
    pub fn new(
        header: &'a ActHeader,
        payload: &'a [u8],
        num_envs: u32,
        run_id: u64,
    ) -> Result<ActBatch<'a>, SchemaError> {
        header.check(num_envs, run_id)?;
        check_len(Channel::Act, num_envs as usize, payload.len())?;
        Ok(ActBatch {
            header,
            actions: &payload[..num_envs as usize],
        })
    }
}

/// Write view of a loaned action sample (stale contents: write all `N`).
#[derive(Debug)]
pub struct ActBatchMut<'a> {
    /// The header (`seq` set at loan; `send_time_ns` stamped at send).
    pub header: &'a mut ActHeader,
    /// `N` action bytes.
    pub actions: &'a mut [u8],
}

const _: () = assert!(size_of::<ActHeader>() == 32);
const _: () = assert!(align_of::<ActHeader>() == 8);
const _: () = assert!(MAX_ENVS <= u32::MAX as usize);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_checks() {
        let h = ActHeader::new(4, 9, 3);
        let acts = [0u8, 1, 2, 6];
        let b = ActBatch::new(&h, &acts, 4, 9).unwrap();
        assert_eq!(b.actions, &acts);
        assert!(matches!(
            ActBatch::new(&h, &acts, 5, 9),
            Err(SchemaError::BatchSize {
                expected: 5,
                wire: 4,
                ..
            })
        ));
        assert!(matches!(
            ActBatch::new(&h, &acts[..3], 4, 9),
            Err(SchemaError::PayloadTooShort { .. })
        ));
        assert!(check_num_envs(0).is_err());
        assert_eq!(check_num_envs(MAX_ENVS).unwrap(), MAX_ENVS as u32);
    }
}
