//! The drivers this binary links, by Player name: the catalog every
//! subcommand that plans or runs a driver is handed.

use troupe_launch::catalog::{Catalog, Entry};

/// Every driver of this build, by name.
pub fn catalog() -> Catalog {
    Catalog::new(vec![
        Entry::of::<troupe_dummy::Dummy>("fixed data at a fixed rate on many interfaces (testing)"),
        Entry::of::<troupe_rangertolaser::RangerToLaser>("republishes a ranger as a laser"),
        Entry::of::<troupe_cameracompress::CameraCompress>("a camera's images compressed to JPEG"),
        Entry::of::<troupe_amcl::Amcl>(
            "adaptive Monte Carlo localization on a map (odometry + laser)",
        ),
        Entry::of::<troupe_mapfile::MapFile>("serves an occupancy map read from an image"),
        Entry::of::<troupe_mapfile::MapScale>("a map device's map at another resolution"),
        Entry::of::<troupe_mapfile::MapCspace>(
            "a map device's map with obstacles grown by the robot's radius",
        ),
        Entry::of::<troupe_vfh::Vfh>(
            "VFH+ obstacle avoidance: velocity and goto commands past obstacles",
        ),
        Entry::of::<troupe_nd::Nd>(
            "Nearness Diagram navigation: goals reached through narrow gaps and clutter",
        ),
        Entry::of::<troupe_wavefront::Wavefront>(
            "global path planner feeding waypoints to a position2d",
        ),
        Entry::of::<troupe_sicklms200::SickLms200>("the SICK LMS200 laser over a serial line"),
        Entry::of::<troupe_urglaser::UrgLaser>(
            "the Hokuyo URG-04LX laser over RS-232 or USB (SCIP 1.1 and 2.0)",
        ),
        Entry::of::<troupe_p2os::P2os>("Pioneer robots (P2OS/ARCOS) over a serial line"),
        Entry::of::<troupe_erratic::Erratic>("the Videre Erratic robot over a serial line"),
        Entry::of::<troupe_wbr914::Wbr914>(
            "White Box Robotics' 914 PC-Bot over its M3 board's serial line",
        ),
        Entry::of::<troupe_log::WriteLog>("writes its required devices' data to a Player text log"),
        Entry::of::<troupe_log::ReadLog>(
            "replays a Player text log as live devices, and is its stack's clock",
        ),
        Entry::of::<troupe_slam_node::SlamNode>(
            "a map built as the robot drives (SLAM): odometry and a laser in, a map and the corrected pose out",
        ),
        Entry::of::<troupe_stage::Stage>(
            "the 2D multi-robot simulator: a Stage world's robots and sensors",
        ),
        Entry::custom(
            troupe_passthrough::NAME,
            "devices of a Player server, or of another robot, served as this robot's own",
            troupe_passthrough::check,
            troupe_passthrough::run,
        ),
    ])
}
