"""Evaluation: reference, metrics, conditions, baselines, simulator, drives, plots, revisit consistency, LiDAR ground truth and the runner."""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".reference": ("WINDOW_M MIN_SPEED FRAME_RATE MAX_GRADE_DEG MAX_PITCH_REL_ROAD_DEG "
                   "MIN_MOVING_FRAMES Reference ReferenceCheck drop_out_of_order frame_times "
                   "travelled_distance smoothed_grade pitch_reference check_reference"),
    ".metrics": ("normal_from_pitch_roll normal_angle wrap_angle wrap_pi frame_errors summarize "
                 "evaluate_drive per_drive_table"),
    ".baselines": "ConstantNormal EulerEKF euler_zyx from_euler_zyx",
    ".simulate": ("GRAVITY ISO8608_N0 ISO8608_CLASSES ImuErrorModel IMU_PRESETS imu_error_model "
                  "VehicleParams RoadParams SpeedParams SimResult simulate simulate_suite "
                  "road_profile suspension_response iso8608_psd TRUTH_COLUMNS TRUTH_ANGLES ROAD_PLANE_WINDOW"),
    ".plots": ("plot_pitch_over_time plot_error_distribution plot_simulation evaluation_plots "
               "pitch_over_time_figure error_distribution_figure"),
    ".drives": "Drive load_real_drive load_real_drives synthetic_drive synthetic_drives",
    ".conditions": ("CONDITIONS frame_signals condition_masks moving_segments segment_centred "
                    "reference_sigma"),
    ".runner": ("Method EVALUATION_METHODS METHODS TUNED SIGMA_BINS run_method evaluate conditions_table "
                "format_table sigma_table summary_table"),
    ".lidar": ("GROUND_FITS LIDAR_EXTRA PATCHWORK_MODULE ROAD_REGION SCAN_SUFFIXES PathRegion RoadRegion bootstrap_spread "
               "compare_to_lidar fit_ground_plane fit_scans kitti_object_rotation lidar_figure lidar_pitch_roll lidar_rotation "
               "lidar_summary lidar_table lidar_transform method_summaries path_region patchwork_available "
               "patchwork_ground planes_pitch_roll planes_rotations plot_lidar read_bin_scan read_scan "
               "read_scan_times read_times scan_files"),
    ".revisit": ("RevisitPairs revisit_pairs ins_at_frames drive_revisit_pairs revisit_differences "
                 "revisit_consistency revisit_table"),
    ".lidar_kitti": ("KittiLidarDrive check_sync_folder drive_path_regions drive_summary find_lidar_drives fit_noise "
                     "is_kitti_sync_folder log_clock oxts_track pooled_summary read_kitti_lidar_drive "
                     "scan_times_on_log"),
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
