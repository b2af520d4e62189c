# V4L2: vivid with two video capture nodes (platform:vivid-000 and -001, each
# offering Y16 as a depth stand-in and YUYV as colour); the reconnect test
# unbinds vivid.0 mid-stream, then reloads the module with vid_cap_nr=5,6.
suite_targets=(test_v4l2_vivid)
suite_modules=("vivid n_devs=2 node_types=0x1,0x1")
suite_init='sleep 1; ls -l /dev/video*'
suite_env=()
suite_may_skip=0
