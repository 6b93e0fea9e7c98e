"""ROS message definitions the sample logs do not carry (gps_msgs), for tests that write them."""

GPS_STATUS = """std_msgs/Header header
uint16 satellites_used
int32[] satellite_used_prn
uint16 satellites_visible
int32[] satellite_visible_prn
int32[] satellite_visible_z
int32[] satellite_visible_azimuth
int32[] satellite_visible_snr
int16 status
uint16 motion_source
uint16 orientation_source
uint16 position_source
"""
GPS_FIX = """std_msgs/Header header
GPSStatus status
float64 latitude
float64 longitude
float64 altitude
float64 track
float64 speed
float64 climb
float64 pitch
float64 roll
float64 dip
float64 time
float64 gdop
float64 pdop
float64 hdop
float64 vdop
float64 tdop
float64 err
float64 err_horz
float64 err_vert
float64 err_track
float64 err_speed
float64 err_climb
float64 err_time
float64 err_pitch
float64 err_roll
float64 err_dip
float64[9] position_covariance
uint8 position_covariance_type
"""
