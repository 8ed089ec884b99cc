//! The map filter on a real robot: `../shared/data/ekf/husky-test1` (a Husky's SBAS fixes,
//! wheel odometry and IMU, 395 s and 359 m) through chassisd's odom frame and the map filter,
//! held to issue 33's figures: GNSS outages no worse than the odom frame's dead reckoning
//! from the same moment nor than a naive one, the whole run within 1.6 m RMS of the fixes,
//! a parked pose that stays put, and wild fixes that never move the pose.

use crate::common;

use chassisd::bench::husky::{HuskyData, report};
use chassisd::fusion::map_filter::MapFilterConfig;

#[test]
fn the_map_filter_holds_on_the_husky_recording() {
    let data = HuskyData::load(&common::shared_data("ekf/husky-test1")).expect("husky data");
    let r = report(&data, MapFilterConfig::default());
    println!("{r}");
    for o in &r.outages {
        assert!(
            o.map_m <= o.odom_m + 0.01,
            "cut at {} s: the map pose ends {:.2} m off, the odom frame from it {:.2} m",
            o.cut_s,
            o.map_m,
            o.odom_m
        );
        assert!(
            o.map_m <= o.naive_m,
            "cut at {} s: {:.2} m, naive dead reckoning {:.1} m",
            o.cut_s,
            o.map_m,
            o.naive_m
        );
    }
    assert!(
        r.rms_to_fixes_m <= 1.6,
        "RMS to the fixes {:.2} m",
        r.rms_to_fixes_m
    );
    assert!(r.parked_without_gnss_m <= 0.05, "{r}");
    assert!(r.parked_with_gnss_m <= 0.3, "{r}");
    assert!(r.wild_runs >= 40 && r.wild_max_m <= 0.5, "{r}");
    // No course in the data: the heading comes from the motion between fixes.
    assert!(r.heading_known_s.is_some_and(|t| t < 30.0), "{r}");
}

/// Issue 33 item 4: the shipped plants' GNSS errors are the Husky's, measured the same way
/// (the RMS change of the error over 0.4 to 40 s, and the rate of steps).
#[test]
fn the_plants_gnss_errors_are_fitted_to_the_husky() {
    use chassisd::bench::gnss_fit::fit;
    use chassisd::sim::plant::PlantConfig;
    let data = HuskyData::load(&common::shared_data("ekf/husky-test1")).expect("husky data");
    for plant in ["plant.mower.toml", "plant.delivery.toml"] {
        let p = PlantConfig::load(&common::repo().join("devices").join(plant)).expect("plant");
        let f = fit(&data, &p, 1);
        println!("{plant}\n{f}");
        for ((lag, d), s) in f.lags_s.iter().zip(&f.data_m).zip(&f.plant_m) {
            assert!(
                (s / d - 1.0).abs() <= 0.25,
                "{plant}: over {lag:.1} s the plant's error moves {s:.2} m, the Husky's {d:.2} m"
            );
        }
        let ratio = f.plant_steps_per_hour / f.data_steps_per_hour;
        assert!((0.5..=2.0).contains(&ratio), "{plant}: steps {f}");
    }
}
