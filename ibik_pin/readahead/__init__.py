"""Read-ahead: each frame's image inputs prepared while the frame before is solved.

frame_images builds one frame's support images and medial axes from its silhouettes; frames_ahead
prepares them ahead, in a forked child process (image_process, the arrays passed in shared memory
through frame_slots) or a thread. Plumbing below the tracker: it may import tasks, vision and the
exceptions, never tracking or the application.
"""
