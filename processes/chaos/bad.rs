//! The bad force samples of `afs chaos`: bursts of one of each kind ([`BadSample`]) on the
//! wrench topic, each sample counted as sent and, if the servo's subscriber was on the service
//! when it went out, as sent to the servo. What the servo's gate made of them comes back in its
//! loop statistics (`LoopStats::injected`, kept across servo restarts), so that every bad sample
//! is accounted for: judged by the gate, or not sent to any servo (one being restarted).

use crate::ipc::Svc;
use crate::rt;
use afs_shared::faults::{BadCounts, BadSample};
use afs_shared::msg::WrenchSample;
use anyhow::{Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::CallbackProgression;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

/// Sends the bursts and counts them.
pub struct BadSampleSender {
    service: PortFactory<Svc, WrenchSample, ()>,
    publisher: Publisher<Svc, WrenchSample, ()>,
    sent: BadCounts,
    to_servo: BadCounts,
}

impl BadSampleSender {
    /// A sender on the wrench topic `service`.
    pub fn new(service: PortFactory<Svc, WrenchSample, ()>) -> Result<Self> {
        let publisher = service
            .publisher_builder()
            .create()
            .context("creating the bad-sample publisher")?;
        Ok(Self {
            service,
            publisher,
            sent: BadCounts::default(),
            to_servo: BadCounts::default(),
        })
    }

    /// Drops the connections to subscribers that died (a killed servo's) as soon as iceoryx2
    /// has cleaned them, not at the next burst: the publisher sends rarely.
    pub fn update_connections(&self) {
        let _ = self.publisher.update_connections();
    }

    /// One of each bad sample, built from the newest genuine one `g`; `servo_pid` is the
    /// running servo's (0: none).
    pub fn burst(&mut self, g: &WrenchSample, servo_pid: i32) {
        for kind in BadSample::ALL {
            // A send reaches every subscriber on the service (it connects new ones first).
            let to_servo = servo_pid != 0 && self.has_subscriber_of(servo_pid);
            if self
                .publisher
                .send_copy(kind.sample(g, rt::monotonic_ns()))
                .is_ok()
            {
                self.sent.count(kind);
                if to_servo {
                    self.to_servo.count(kind);
                }
            }
        }
    }

    /// Bad samples sent, by kind.
    pub fn sent(&self) -> BadCounts {
        self.sent
    }

    /// Of those, sent while the servo's subscriber was on the service.
    pub fn to_servo(&self) -> BadCounts {
        self.to_servo
    }

    /// True when the process `pid` has a subscriber on the wrench topic.
    fn has_subscriber_of(&self, pid: i32) -> bool {
        let mut found = false;
        self.service.dynamic_config().list_subscribers(|s| {
            found = s.node_id.pid::<Svc>().is_ok_and(|p| p.value() == pid);
            if found {
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
        found
    }
}
