use super::*;
use crate::image::components::Components;
use crate::image::data::PixelData;
use crate::irradiance::record::tests::flat_record;
use crate::shading::request::AmbientRequest;
use glam::Vec3;

/// A request with every field set, for tests of code that moves requests around.
pub(crate) fn sample_request(pixel: u32) -> AmbientRequest {
    AmbientRequest {
        pixel,
        layer: Layer::Specular,
        specular_depth: 2,
        position: Vec3::new(1.0, 2.0, 3.0),
        geometric_normal: Vec3::Y,
        normal: Vec3::Y,
        facing_normal: -Vec3::Y,
        coefficient: Vec3::new(0.1, 0.2, 0.3),
        weight: 0.5,
        direction: Vec3::X,
        material: 7,
        stream: 0xdead_beef_0000_0001,
        centre_ray: Some((Vec3::new(0.0, 1.0, 5.0), -Vec3::Z)),
        distance: 4.5,
    }
}

fn record(i: u32) -> Record {
    let mut r = flat_record(0.1 + i as f32, 0.5);
    r.position = Vec3::new(i as f32, 2.0, -1.0);
    r
}

fn pixel(v: f32) -> PixelValue {
    PixelValue {
        components: Components {
            emission: Vec3::splat(v),
            direct: Vec3::X,
            specular: Vec3::Y,
            indirect: Vec3::Z,
        },
        records: 2.0,
        data: pixel_data(),
    }
}

/// Data layers with every field set, and two Cryptomatte IDs (their bits must survive).
fn pixel_data() -> PixelData {
    let mut sum = crate::image::data::PixelDataSum::new(2);
    for (depth, name) in [(2.5, "floor"), (1.5, "wall")] {
        let hit = crate::image::data::SampleHit {
            position: Vec3::new(1.0, -2.0, depth),
            depth,
            normal: Vec3::Y,
            object: crate::image::cryptomatte::id_of(name),
            material: crate::image::cryptomatte::id_of("paint"),
        };
        sum.add(Vec3::new(0.5, 0.25, 0.125), Some(hit));
    }
    sum.set_noise(crate::image::data::LayerNoise {
        direct: 0.75,
        specular: 0.0625,
        indirect: 3.5,
    });
    sum.finish()
}

fn grid_sample(v: f32) -> crate::irradiance::last_bounce::GridSample {
    crate::irradiance::last_bounce::GridSample {
        position: Vec3::new(v, 2.0 * v, -v),
        normal: Vec3::Y,
        received: crate::irradiance::last_bounce::Received {
            direct: Vec3::splat(v.abs()),
            indirect: Vec3::new(0.25, 0.5, 0.125),
        },
    }
}

/// One message of every kind, with content in every field.
fn every_message() -> Vec<Message> {
    let records = || Records::from(vec![record(1), record(2)]);
    let mut report = RankReport {
        rank: 3,
        role: "pa".into(),
        ..Default::default()
    };
    report.queue_lengths = vec![(0.5, 7)];
    vec![
        Message::Heartbeat,
        Message::InitialRecords(records()),
        Message::PrepassStart(Records::default()),
        Message::PrepassRound(vec![(3, record(0)), (9, record(4))]),
        Message::PrepassSites(vec![4, 0, 17, u32::MAX]),
        Message::TileClaims(vec![1, 3, 5]),
        Message::PrepassKept(crate::prepass::Kept::End(77)),
        Message::PrepassKept(crate::prepass::Kept::Round(
            crate::prepass::RoundLog {
                sites: 9,
                records: 1,
                compute_s: 0.5,
                pool_s: 0.25,
                seconds: 1.0,
                bytes: 132,
            },
            vec![(40, record(3))],
        )),
        Message::PrepassGrid(vec![(0, vec![]), (4, vec![grid_sample(1.0), grid_sample(-2.5)])]),
        // Rows of 0, 3, 8 and 11 flags: the bits pack into whole bytes, and the last one's rest.
        Message::PrepassPixels(vec![
            (2, vec![]),
            (5, vec![true, false, true]),
            (6, (0..8).map(|i| i % 3 == 0).collect()),
            (9, (0..11).map(|i| i % 2 == 1).collect()),
        ]),
        Message::WorkRequest {
            thread: 2,
            finished: None,
        },
        Message::WorkRequest {
            thread: 1,
            finished: Some(FinishedTile {
                tile: 7,
                requests: 11,
                pixels: TilePixels::Values(vec![pixel(0.5), pixel(1.5)]),
            }),
        },
        Message::WorkRequest {
            thread: 1,
            finished: Some(FinishedTile {
                tile: 8,
                requests: 0,
                pixels: TilePixels::Encoded(EncodedTile {
                    chunks: vec![((0, 1), vec![1, 2, 3]), ((1, 1), vec![9; 40])],
                    preview: vec![[1, 2, 3, 129], [0; 4]],
                    log: LogLuminance::from_parts(-(1 << 70), 2),
                }),
            }),
        },
        Message::Work {
            thread: 3,
            tile: Some(42),
            records: records(),
        },
        Message::Work {
            thread: 0,
            tile: None,
            records: Records::default(),
        },
        Message::RecordsUp {
            thread: 5,
            records: records(),
        },
        Message::RecordsDown {
            thread: 5,
            records: records(),
        },
        Message::RecordsBroadcast {
            records: records(),
            last: true,
        },
        Message::FinalRecords(records()),
        Message::Stats(Box::new(report)),
        Message::Requests(Requests::from(vec![sample_request(5), sample_request(99)])),
        Message::Forwarded(Requests::default()),
        Message::Idle {
            sent: 10,
            helped: 3,
            records: records(),
        },
        Message::PaStatus {
            queue: 4,
            done: 1 << 40,
            records: Records::default(),
        },
        Message::ForwardOrder {
            to: 4,
            count: 17,
            to_pa: true,
        },
        Message::Finish,
        Message::Results(vec![RequestResult {
            pixel: 9,
            layer: Layer::Specular,
            value: Vec3::new(0.1, 0.2, 0.3),
        }]),
    ]
}

#[test]
fn every_message_round_trips() {
    for message in every_message() {
        let bytes = message.encode();
        let back = Message::decode(message.tag(), &bytes).unwrap_or_else(|e| panic!("{message:?}: {e}"));
        assert_eq!(back, message);
    }
}

#[test]
fn tags_are_distinct_and_name_their_kind() {
    let messages = every_message();
    for m in &messages {
        assert_eq!(Kind::of_tag(m.tag()).map(|(k, _)| k), Some(m.kind()));
    }
    assert_eq!(Kind::of_tag(Kind::Work.for_thread(7)), Some((Kind::Work, 7)));
    assert_eq!(
        Kind::of_tag(Kind::RecordsDown.for_thread(MAX_THREADS)),
        Some((Kind::RecordsDown, MAX_THREADS))
    );
    assert_eq!(Kind::of_tag(0), None);
    assert_eq!(Kind::of_tag(999), None);
    assert!(Message::decode(999, &[PROTOCOL_VERSION]).is_err());
}

#[test]
fn truncated_or_padded_messages_are_refused() {
    for message in every_message() {
        let bytes = message.encode();
        for cut in 0..bytes.len() {
            // A statistics message is JSON: every cut of it is malformed JSON too.
            assert!(
                Message::decode(message.tag(), &bytes[..cut]).is_err(),
                "{message:?} cut at {cut} of {}",
                bytes.len()
            );
        }
        let mut padded = bytes.clone();
        padded.push(0);
        assert!(
            Message::decode(message.tag(), &padded).is_err(),
            "{message:?} with a byte more"
        );
    }
}

#[test]
fn another_protocol_version_is_refused() {
    let mut bytes = Message::Finish.encode();
    bytes[0] = PROTOCOL_VERSION + 1;
    let e = Message::decode(Kind::Finish.tag(), &bytes).unwrap_err();
    assert!(e.0.contains("version"), "{e}");
}

#[test]
fn a_corrupted_record_is_dropped_and_counted_but_fails_a_prepass_round() {
    let message = Message::InitialRecords(Records::from(vec![record(1), record(2)]));
    let mut bytes = message.encode();
    // Version, count, then the records: damage the second one.
    bytes[1 + 4 + RECORD_BYTES + 5] ^= 0xff;
    match Message::decode(message.tag(), &bytes).unwrap() {
        Message::InitialRecords(r) => assert_eq!((r.records, r.rejected), (vec![record(1)], 1)),
        other => panic!("{other:?}"),
    }
    let round = Message::PrepassRound(vec![(0, record(1)), (1, record(2))]);
    let mut bytes = round.encode();
    bytes[1 + 4 + (4 + RECORD_BYTES) + 4 + 5] ^= 0xff;
    assert!(Message::decode(round.tag(), &bytes).is_err());
}

#[test]
fn bad_requests_are_refused_one_by_one() {
    let message = Message::Requests(Requests::from(vec![sample_request(5), sample_request(6)]));
    let mut bytes = message.encode();
    // The first request's shading normal (after pixel, layer, depth, position, geometric
    // normal) becomes NaN.
    let normal = 1 + 4 + 12 + 24;
    bytes[normal..normal + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    match Message::decode(message.tag(), &bytes).unwrap() {
        Message::Requests(r) => {
            assert_eq!(r.rejected, 1);
            assert_eq!(r.requests.len(), 1);
            assert_eq!(r.requests[0].pixel, 6);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        empty_requests(),
        Message::Requests(Requests::default()).encode().as_slice()
    );
}

#[test]
fn unhealthy_pixels_and_results_are_refused() {
    let request = |v: f32| Message::WorkRequest {
        thread: 0,
        finished: Some(FinishedTile {
            tile: 1,
            requests: 0,
            pixels: TilePixels::Values(vec![pixel(v)]),
        }),
    };
    for bad in [f32::NAN, -1.0, f32::INFINITY] {
        assert!(Message::decode(Kind::WorkRequest.tag(), &request(bad).encode()).is_err());
        // The same in a data layer: a depth, or a coverage.
        let mut with_bad_data = request(1.0);
        fn first_pixel(message: &mut Message) -> &mut PixelValue {
            match message {
                Message::WorkRequest {
                    finished:
                        Some(FinishedTile {
                            pixels: TilePixels::Values(pixels),
                            ..
                        }),
                    ..
                } => &mut pixels[0],
                _ => unreachable!("a request with values"),
            }
        }
        first_pixel(&mut with_bad_data).data.depth = bad;
        assert!(Message::decode(Kind::WorkRequest.tag(), &with_bad_data.encode()).is_err());
        first_pixel(&mut with_bad_data).data.depth = 1.0;
        first_pixel(&mut with_bad_data).data.object[0].coverage = bad;
        assert!(Message::decode(Kind::WorkRequest.tag(), &with_bad_data.encode()).is_err());
        // A result's light may not be NaN or infinite (it is added to a pixel as it is).
        let value = Vec3::new(1.0, bad, 1.0);
        let result = Message::Results(vec![RequestResult {
            pixel: 1,
            layer: Layer::Indirect,
            value,
        }]);
        assert_eq!(
            Message::decode(Kind::Results.tag(), &result.encode()).is_err(),
            !bad.is_finite()
        );
    }
    let results = Message::Results(vec![RequestResult {
        pixel: 1,
        layer: Layer::Indirect,
        value: Vec3::ONE,
    }]);
    let mut bytes = results.encode();
    bytes[1 + 4 + 4] = 9; // no layer 9
    assert!(Message::decode(results.tag(), &bytes).is_err());
}

#[test]
fn a_requests_centre_ray_travels_and_a_bad_one_is_refused() {
    // With and without the pixel's centre ray: both arrive as sent.
    let alone = AmbientRequest {
        centre_ray: None,
        ..sample_request(7)
    };
    let message = Message::Requests(Requests::from(vec![sample_request(5), alone]));
    let bytes = message.encode();
    assert_eq!(bytes.len(), 1 + 4 + 2 * REQUEST_BYTES);
    match Message::decode(message.tag(), &bytes).unwrap() {
        Message::Requests(r) => assert_eq!(r.requests, vec![sample_request(5), alone]),
        other => panic!("{other:?}"),
    }
    // The first request's centre direction (after the 100 bytes of the rest, the flag and the
    // origin) no longer unit length: refused, the second still taken.
    let mut bytes = bytes;
    let direction = 1 + 4 + 100 + 4 + 12;
    bytes[direction..direction + 4].copy_from_slice(&3.0f32.to_le_bytes());
    match Message::decode(message.tag(), &bytes).unwrap() {
        Message::Requests(r) => assert_eq!((r.rejected, r.requests), (1, vec![alone])),
        other => panic!("{other:?}"),
    }
    // A flag that is neither 0 nor 1 is refused too.
    let mut bytes = message.encode();
    bytes[1 + 4 + 100] = 2;
    match Message::decode(message.tag(), &bytes).unwrap() {
        Message::Requests(r) => assert_eq!(r.rejected, 1),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_finished_tile_counts_the_bytes_it_takes_in_its_message() {
    let empty = Message::WorkRequest {
        thread: 0,
        finished: None,
    }
    .encode()
    .len();
    let encoded = TilePixels::Encoded(EncodedTile {
        chunks: vec![((3, 4), vec![7; 33]), ((4, 4), vec![1; 5])],
        preview: vec![[9; 4]; 6],
        log: LogLuminance::from_parts(12345, 6),
    });
    for pixels in [TilePixels::Values(vec![pixel(0.5), pixel(2.0)]), encoded] {
        let message = Message::WorkRequest {
            thread: 0,
            finished: Some(FinishedTile {
                tile: 2,
                requests: 0,
                pixels: pixels.clone(),
            }),
        };
        // The tile's index and requests, and the byte saying which form its pixels take.
        assert_eq!(message.encode().len(), empty + 4 + 4 + 1 + pixels.wire_bytes());
    }
}
