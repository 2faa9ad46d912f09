"""The labeling UI: a viser app in which a labeler replays MuJoCo segments in 3D and labels them
bad / neutral / good from the keyboard. It reaches the labeling service over HTTP only and imports
no torch. Start it with `collie label-ui --api URL`."""
