//! The crate's only `unsafe` code, in small helpers:
//!
//! - [`assume_init_slice`] / [`assume_init_response`]: turn a freshly loaned,
//!   "uninitialised" shared-memory chunk into an initialised one *without
//!   writing it*, so the simulator's step can be the only write of an
//!   observation (no memset, no copy).
//! - [`split_slice_sample`]: borrow a sample's user header and payload
//!   mutably at the same time (iceoryx2 offers one `&mut` accessor for each).
//! - [`force_remove_services`]: iceoryx2's last-resort removal of a
//!   service left corrupted by a crash, guarded by a check that no other
//!   node of the prefix is alive.
//! - [`monotonic_ns`]: `CLOCK_MONOTONIC` in nanoseconds; [`type_name_of`]:
//!   the type name iceoryx2 records for a payload type.
//! - [`prefetch`]: start loading a few bytes' cache lines (an x86 hint).
//!
//! ## Why skipping initialisation is sound here
//!
//! iceoryx2 hands loans out as `MaybeUninit<T>` because in general a chunk
//! may never have been written. For this crate's channels, every byte of a
//! data segment is nonetheless an initialised byte:
//!
//! 1. the segment is a POSIX shared-memory object, which the kernel
//!    zero-fills when it is sized; bytes that come from outside the Rust
//!    abstract machine (a `mmap`) are initialised, like file contents read
//!    through a memory map;
//! 2. afterwards the only writes into a chunk are whole values of the
//!    channel's element or payload type, and every such type here is
//!    [`bytemuck::Pod`]: it has no padding, so a write never leaves
//!    uninitialised bytes behind (iceoryx2 checks type name, size and
//!    alignment when a service is opened, so no other type can share the
//!    segment);
//! 3. every bit pattern is a valid value of a `Pod` type.
//!
//! Hence a loaned chunk holds valid (if stale: the previous sample's) values.
//! The stale contents are why the views document that the writer must
//! overwrite every meta record and cell; debug builds fill loans with a
//! sentinel so a forgotten write shows up.
#![allow(unsafe_code)]

use core::fmt::Debug;
use core::mem::MaybeUninit;

use bytemuck::Pod;
use iceoryx2::node::Node;
use iceoryx2::prelude::{
    CallbackProgression, MessagingPattern, NodeState, ServiceName, ZeroCopySend,
};
use iceoryx2::response_mut::ResponseMut;
use iceoryx2::response_mut_uninit::ResponseMutUninit;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::Service;

/// Marks a slice loan as initialised without writing it (see the module doc).
pub(crate) fn assume_init_slice<S, T, H>(
    sample: SampleMutUninit<S, [MaybeUninit<T>], H>,
) -> SampleMut<S, [T], H>
where
    S: Service,
    T: Pod + ZeroCopySend + Debug,
    H: ZeroCopySend + Debug,
{
    // SAFETY: the chunk lies in a kernel-zero-filled shared-memory segment
    // that only ever receives whole `T` values, `T: Pod` has no padding and
    // accepts every bit pattern, so all elements are initialised and valid
    // (module doc, points 1-3).
    unsafe { sample.assume_init() }
}

/// Marks a fixed-size response loan as initialised without writing it.
pub(crate) fn assume_init_response<S, T, H>(
    response: ResponseMutUninit<S, MaybeUninit<T>, H>,
) -> ResponseMut<S, T, H>
where
    S: Service,
    T: Pod + ZeroCopySend + Debug,
    H: ZeroCopySend + Debug,
{
    // SAFETY: same argument as `assume_init_slice`: the response segment is
    // kernel-zero-filled and only ever receives whole `T: Pod` values, so
    // the chunk holds a valid `T`.
    unsafe { response.assume_init() }
}

/// Mutable user header and payload of one sample at the same time.
pub(crate) fn split_slice_sample<S, T, H>(sample: &mut SampleMut<S, [T], H>) -> (&mut H, &mut [T])
where
    S: Service,
    T: ZeroCopySend + Debug,
    H: ZeroCopySend + Debug,
{
    let header: *mut H = sample.user_header_mut();
    let payload = sample.payload_mut();
    // SAFETY: `header` points at the chunk's user header, which iceoryx2
    // places before the payload without overlap (`user_header_ptr` +
    // `size_of::<H>()` <= `payload_ptr`); the pointer stays valid while
    // `sample` (borrowed mutably for the returned lifetime) keeps the chunk
    // loaned, and no other reference to the header exists: the
    // `user_header_mut` borrow it came from has ended, and `payload` covers
    // only the payload bytes.
    let header = unsafe { &mut *header };
    (header, payload)
}

/// Removes the given services by force, but only while `node` is the sole
/// live node under its prefix (dead nodes are fine: they are what left the
/// services behind). Returns how many services existed and were removed,
/// or the number of other live nodes as `Err`.
pub(crate) fn force_remove_services<S: Service>(
    node: &Node<S>,
    services: &[(ServiceName, MessagingPattern)],
) -> Result<Result<usize, String>, usize> {
    let mut others_alive = 0;
    let listed = Node::<S>::list(node.config(), |state| {
        if let NodeState::Alive(view) = &state
            && iceoryx2::node::NodeView::id(view) != node.id()
        {
            others_alive += 1;
        }
        CallbackProgression::Continue
    });
    if let Err(e) = listed {
        return Ok(Err(format!("{e:?}")));
    }
    if others_alive > 0 {
        return Err(others_alive);
    }
    let mut removed = 0;
    for (name, pattern) in services {
        // SAFETY: `force_remove_service` requires that no other process uses
        // the service. Every process using a service of this prefix does so
        // through a node registered under the prefix, and the listing above
        // found no live node but `node`, which has not opened any service
        // of the run (`PipelineNode::force_remove_stale_services` checks).
        match unsafe { node.force_remove_service(name, *pattern) } {
            Ok(true) => removed += 1,
            Ok(false) => {}
            Err(e) => return Ok(Err(format!("{name}: {e:?}"))),
        }
    }
    Ok(Ok(removed))
}

/// The type name iceoryx2 records for `T` (its `#[type_name]`).
pub(crate) fn type_name_of<T: ZeroCopySend + ?Sized>() -> String {
    // SAFETY: `ZeroCopySend::type_name` is `unsafe` because implementors
    // promise that equal names mean equal layouts; calling it only reads a
    // `&'static str` and has no precondition.
    unsafe { <T as ZeroCopySend>::type_name() }.to_owned()
}

/// Current `CLOCK_MONOTONIC` time in nanoseconds: comparable between
/// processes on one machine, so `now - header.send_time_ns` is a one-way
/// latency.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable `timespec`; CLOCK_MONOTONIC is always
    // supported on Linux, so the call only writes `ts`.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0, "clock_gettime(CLOCK_MONOTONIC) failed");
    (ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64
}

/// Asks the CPU to start loading every cache line of `bytes` (x86-64
/// `prefetcht0`; nothing elsewhere). A hint only: it reads nothing and
/// cannot fault, whatever the address.
///
/// Used for data another core has just written: the loads then overlap
/// instead of each one waiting for the previous line to cross cores.
#[inline]
pub(crate) fn prefetch(bytes: &[u8]) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        const LINE: usize = 64;
        let start = bytes.as_ptr() as usize & !(LINE - 1);
        let end = bytes.as_ptr() as usize + bytes.len();
        for line in (start..end).step_by(LINE) {
            // SAFETY: a prefetch is a hint that never faults and reads no
            // value into the program, so any address is allowed.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(line as *const i8) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = bytes;
}
