mod bundle;
mod controller;
mod opencv;
mod tracker;
